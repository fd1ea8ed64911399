"""Property-based fuzzing of every form on every page, as every persona (Hypothesis).

The pages are the matrix's GET pages with ids of team A's things. Every form found on them
(logout aside: it would end the persona's session) is submitted with its real CSRF token and
values Hypothesis draws per field: any text (lone surrogates included), huge and negative
integers, times at the edges of the calendar, long strings, junk choices. The test fails on
any 5xx and on any traceback in CloudSim's log. Seeded like the API fuzzer (tests/web/fuzz.py).
"""

from __future__ import annotations

import io
import time
from dataclasses import dataclass, field
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import urlencode

import pytest
from flask import Flask
from flask.testing import FlaskClient
from hypothesis import given
from hypothesis import strategies as st

from cloudsim.auth.policy import SYSTEM
from cloudsim.extensions import db
from cloudsim.jobs.service import enqueue
from cloudsim.models import User
from tests.conftest import log_in
from tests.web.fuzz import PERSONAS, SEED, populate, seeded, watched_log
from tests.web.test_authorization_matrix import MATRIX, _url

EXAMPLES = {"anon": 40, "user_a": 30, "user_b": 20, "officer": 50, "admin": 50}
SKIPPED_ACTIONS = ("/logout",)


@dataclass
class Form:
    """A form as the browser would submit it."""

    action: str
    multipart: bool
    fields: dict[str, list[str]] = field(default_factory=dict)  # name -> options ([] = free)
    kinds: dict[str, str] = field(default_factory=dict)  # name -> input type
    defaults: dict[str, str] = field(default_factory=dict)  # name -> the value the page offers


class FormParser(HTMLParser):
    """Collect the POST forms of a page with their fields and choices."""

    def __init__(self) -> None:
        super().__init__()
        self.forms: list[Form] = []
        self._select: str | None = None

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = {k: v or "" for k, v in attrs}
        if tag == "form" and a.get("method", "get").lower() == "post":
            self.forms.append(Form(a.get("action", ""), "multipart" in a.get("enctype", "")))
        elif not self.forms or not a.get("name"):
            if tag == "option" and self._select and self.forms:
                form = self.forms[-1]
                form.fields[self._select].append(a.get("value", ""))
                if "selected" in a or self._select not in form.defaults:
                    form.defaults[self._select] = a.get("value", "")
            return
        elif tag in ("input", "textarea", "select"):
            name = a["name"]
            form = self.forms[-1]
            form.kinds[name] = a.get("type", tag)
            form.fields[name] = [a.get("value", "")] if name == "csrf_token" else []
            if a.get("value"):
                form.defaults[name] = a["value"]
            if tag == "select":
                self._select = name

    def handle_endtag(self, tag: str) -> None:
        if tag == "select":
            self._select = None


def _text_values() -> st.SearchStrategy[str]:
    return st.one_of(
        st.text(max_size=40),
        st.text(alphabet=st.characters(codec=None), max_size=10),  # lone surrogates too
        st.integers().map(str),
        st.integers(min_value=2**31, max_value=2**80).map(lambda n: str(-n if n % 2 else n)),
        st.sampled_from(
            [
                "",
                " ",
                "0",
                "-1",
                "9" * 25,
                "7" * 5000,
                "1e400",
                "NaN",
                "0001-01-01T00:00",
                "9999-12-31T23:59",
                "2030-02-30T10:00",
                "Asia/Tokyo",
                "Pacific/Kiritimati",
                "x" * 300,
                "\x00",
                "a@b",
                "tasks: [{name: x, world: vrc_task_1, start: 0001-01-01, stop: 9999-12-31}]",
            ]
        ),
    )


# A valid value per input type, so that most submissions pass validation but for a field or two
# and reach the service and the database with the hostile ones.
VALID = {
    "email": "fuzz@example.org",
    "password": "a long enough password",
    "datetime-local": "2030-01-01T09:00",
    "number": "1",
    "file": "tasks: [{name: Fuzz, world: vrc_task_1, start: 2030-01-01 09:00, "
    "stop: 2030-01-02 09:00}]",
}


def _valid(form: Form, name: str) -> str:
    return form.defaults.get(name) or VALID.get(form.kinds[name], "Fuzz value")


def _values(form: Form) -> st.SearchStrategy[dict[str, str | None]]:
    """Draw a value for every field (None: left out), mostly valid, sometimes hostile."""
    strategies: dict[str, st.SearchStrategy[str | None]] = {}
    for name, options in form.fields.items():
        valid = st.just(_valid(form, name))
        if name == "csrf_token":
            strategies[name] = st.just(options[0])
        elif form.kinds[name] == "checkbox":
            strategies[name] = st.sampled_from(["y", None])
        elif options:
            hostile = st.one_of(st.sampled_from(options), _text_values(), st.none())
            strategies[name] = st.one_of(valid, valid, hostile)
        else:
            strategies[name] = st.one_of(valid, valid, _text_values(), st.none())
    return st.fixed_dictionaries(strategies)


def _submit(client: FlaskClient, form: Form, values: dict[str, str | None]) -> int:
    present = {k: v for k, v in values.items() if v is not None}
    if form.multipart:
        data: dict[str, object] = {
            k: v.encode("utf-8", "surrogatepass").decode("utf-8", "replace")
            for k, v in present.items()
            if form.kinds[k] != "file"
        }
        for name in (k for k in present if form.kinds[k] == "file"):
            data[name] = (io.BytesIO(present[name].encode("utf-8", "surrogatepass")), "x.yaml")  # type: ignore[union-attr]
        return client.post(form.action, data=data, content_type="multipart/form-data").status_code
    body = urlencode(present, encoding="utf-8", errors="surrogatepass")
    return client.post(
        form.action, data=body, content_type="application/x-www-form-urlencoded"
    ).status_code


def _forms(
    app: Flask, client: FlaskClient, people: dict[str, User | None], tmp: Path
) -> list[Form]:
    """Return every distinct form on every page this persona can open."""
    team_a = people["user_a"].team  # type: ignore[union-attr]
    job_id = enqueue("diagnostics", SYSTEM, team_id=team_a.id).id
    constellation_id = db.session.scalar(
        db.select(db.text("id")).select_from(db.text("constellations"))
    )
    found: dict[tuple[str, tuple[str, ...]], Form] = {}
    pages = sorted(e for e, m in MATRIX if m == "GET" and not e.startswith(("api", "static")))
    for endpoint in pages:
        url = _url(app, endpoint, team_a, people["user_a"], job_id, constellation_id, tmp)  # type: ignore[arg-type]
        response = client.get(url)
        db.session.rollback()
        if response.status_code != 200 or response.mimetype != "text/html":
            continue
        parser = FormParser()
        parser.feed(response.get_data(as_text=True))
        for form in parser.forms:
            form.action = form.action or url  # a form without an action posts to its page
            if not form.action.startswith(SKIPPED_ACTIONS):
                found.setdefault((form.action, tuple(sorted(form.fields))), form)
    return list(found.values())


def _fuzz_form(
    client: FlaskClient, form: Form, examples: int, crashes: list[str]
) -> tuple[int, int]:
    """Submit one form `examples` times; note every 5xx in crashes; return the count sent and
    the count the app accepted (below 400)."""
    sent = accepted = 0

    @seeded(examples)
    @given(values=_values(form))
    def submit(values: dict[str, str | None]) -> None:
        nonlocal sent, accepted
        sent += 1
        status = _submit(client, form, values)
        accepted += status < 400
        db.session.rollback()
        if status >= 500:
            crashes.append(f"{form.action} {status}: {values!r}"[:500])
        assert status < 500

    try:
        submit()
    except AssertionError:
        pass  # already in crashes, the shrunk example last
    return sent, accepted


@pytest.mark.parametrize("persona", PERSONAS)
def test_every_form_survives_fuzzing(
    app: Flask, people: dict[str, User | None], persona: str, tmp_path: Path
) -> None:
    populate(app, people, tmp_path)
    client = app.test_client()
    if people[persona] is not None:
        log_in(client, people[persona])  # type: ignore[arg-type]
    forms = _forms(app, client, people, tmp_path)
    assert forms, "no form found: the crawl is broken"
    started, sent, accepted, crashes = time.monotonic(), 0, 0, []
    with watched_log() as log:
        for form in forms:
            counts = _fuzz_form(client, form, EXAMPLES[persona], crashes)
            sent, accepted = sent + counts[0], accepted + counts[1]
    print(
        f"\n{persona}: {len(forms)} forms, {sent} submissions ({accepted} accepted), "
        f"{time.monotonic() - started:.1f} s, seed {SEED}"
    )
    # Submissions that all bounce off the CSRF check or a lost login reach no service at all.
    assert accepted > 0 or people[persona] is None, "no submission was accepted"
    assert not crashes, "\n".join(crashes[-10:])
    assert not log.records, f"the app logged errors:\n{log.report()}"
