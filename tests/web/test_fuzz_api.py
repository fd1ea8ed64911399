"""Property-based fuzzing of every API operation, as every persona (schemathesis on Hypothesis).

Each operation of the OpenAPI document gets valid requests (positive) and requests that break
its schema (negative). The test fails on any 5xx, any answer that does not match the documented
status codes, content type or body schema, and on any traceback in CloudSim's log. The seed is
fixed (tests/web/fuzz.py), so a failure reproduces; the example counts keep it under a minute.
"""

from __future__ import annotations

import time
from pathlib import Path

import pytest
import schemathesis
from flask import Flask
from hypothesis import given
from schemathesis import GenerationMode
from schemathesis.checks import not_a_server_error
from schemathesis.specs.openapi.checks import (
    content_type_conformance,
    response_schema_conformance,
    status_code_conformance,
)

from cloudsim.extensions import db
from cloudsim.models import User
from tests.conftest import token_for
from tests.web.fuzz import PERSONAS, SEED, populate, seeded, watched_log

# Examples per operation and mode: anonymous calls all end at the 401, the others go deep.
EXAMPLES = {"anon": 3, "user_a": 8, "user_b": 5, "officer": 8, "admin": 8}
CHECKS = [
    not_a_server_error,
    status_code_conformance,
    content_type_conformance,
    response_schema_conformance,
]
FIGURES: dict[str, tuple[int, int, float]] = {}


def _fuzz_operation(
    operation: object, mode: GenerationMode, headers: dict[str, str], examples: int
) -> tuple[int, int]:
    """Run one operation's examples in one mode; return how many requests were sent and how
    many of them were accepted (2xx)."""
    sent = accepted = 0

    @seeded(examples)
    @given(case=operation.as_strategy(generation_mode=mode))  # type: ignore[attr-defined]
    def run(case: schemathesis.Case) -> None:
        nonlocal sent, accepted
        sent += 1
        try:
            response = case.call_and_validate(headers=headers, checks=CHECKS)
            accepted += response.status_code < 300
        finally:
            db.session.rollback()

    run()
    return sent, accepted


def _summary(exc: BaseException) -> str:
    """Return a failure's lines that name the broken check, the data and how to reproduce."""
    text = (
        str(exc)
        if not isinstance(exc, BaseExceptionGroup)
        else "\n".join(str(e) for e in exc.exceptions)
    )
    return text[:1500]


def _api_routes(app: Flask) -> int:
    return sum(
        len(rule.methods - {"HEAD", "OPTIONS"})  # type: ignore[operator]
        for rule in app.url_map.iter_rules()
        if rule.rule.startswith("/api/v1/") and not rule.rule.endswith("openapi.json")
    )


@pytest.mark.parametrize("persona", PERSONAS)
def test_every_operation_survives_fuzzing(
    app: Flask, people: dict[str, User | None], persona: str, tmp_path: Path
) -> None:
    populate(app, people, tmp_path)
    user = people[persona]
    headers = token_for(user) if user is not None else {}
    schema = schemathesis.openapi.from_wsgi("/api/v1/openapi.json", app)
    operations = [result.ok() for result in schema.get_all_operations()]
    assert len(operations) == _api_routes(app)  # the whole API, not a part of it
    started, sent, accepted, failures = time.monotonic(), 0, 0, []
    with watched_log() as log:
        for operation in operations:
            for mode in (GenerationMode.POSITIVE, GenerationMode.NEGATIVE):
                try:
                    counts = _fuzz_operation(operation, mode, headers, EXAMPLES[persona])
                    sent, accepted = sent + counts[0], accepted + counts[1]
                except (Exception, BaseExceptionGroup) as exc:  # report all, not the first
                    failures.append(f"{operation.label} ({mode.value}): {_summary(exc)}")
    FIGURES[persona] = (len(operations), sent, time.monotonic() - started)
    print(
        f"\n{persona}: {len(operations)} operations, {sent} requests ({accepted} accepted), "
        f"{FIGURES[persona][2]:.1f} s, seed {SEED}"
    )
    # A fuzzer whose every request bounces off authentication tests nothing behind it.
    assert accepted > 0 or user is None, "no request was accepted: the fuzzer never got in"
    assert not failures, f"{len(failures)} failure(s):\n" + "\n\n".join(failures)
    assert not log.records, f"the app logged errors:\n{log.report()}"
