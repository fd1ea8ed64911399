"""World documents nested 5,000 deep, or made of YAML aliases, are refused with a clear 400 on
the page and the API and one error line in `cloudsim world update`; nothing changes."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import pytest
from click.testing import Result
from flask import Flask

from cloudsim.competition.season import parse_season
from cloudsim.errors import InvalidInput
from cloudsim.models import Role
from cloudsim.providers.service import servers_settings
from tests.competition.test_cli import run  # noqa: F401 (the fixture)
from tests.conftest import csrf_token, log_in, make_user, token_for

DEEP_JSON = "[" * 5000 + "]" * 5000
DEEP_YAML = "a:\n" + "".join(" " * i + "- \n" for i in range(1, 300))
# ten levels of ten aliases: 10^10 leaves once copied as JSON
ALIASES = "a: &a [x, x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"{chr(98 + i)}: &{chr(98 + i)} [{', '.join(['*' + chr(97 + i)] * 10)}]\n" for i in range(9)
)


@pytest.mark.parametrize("text", [DEEP_JSON, DEEP_YAML, ALIASES], ids=["json", "yaml", "aliases"])
def test_the_page_refuses_deep_and_aliased_documents(app: Flask, text: str) -> None:
    client = app.test_client()
    log_in(client, make_user(Role.ADMIN))
    page = client.get("/worlds").get_data(as_text=True)
    answer = client.post("/worlds", data={"csrf_token": csrf_token(page), "text": text})
    body = answer.get_data(as_text=True)
    assert answer.status_code == 400, body[:500]
    assert "nested deeper than" in body or "aliases are not accepted" in body


def test_the_api_refuses_a_deep_document(app: Flask) -> None:
    admin = token_for(make_user(Role.ADMIN))
    body = '{"document": ' + DEEP_JSON + "}"
    answer = app.test_client().put(
        "/api/v1/worlds/vrc_task_1",
        data=body,
        headers={**admin, "Content-Type": "application/json"},
    )
    assert answer.status_code == 400, answer.get_data(as_text=True)[:500]


def test_the_command_line_refuses_a_deep_document(
    run: Callable[..., Result],  # noqa: F811
    tmp_path: Path,
) -> None:
    path = tmp_path / "deep.json"
    path.write_text(DEEP_JSON)
    refused = run("world", "update", str(path))
    assert (refused.exit_code != 0 and refused.exception is None) or isinstance(
        refused.exception, SystemExit
    )
    assert "nested deeper than" in refused.output and "Traceback" not in refused.output
    assert json.loads(run("world", "list", "--json").output)[0]["version"] == 1


@pytest.mark.parametrize("text", [DEEP_JSON, DEEP_YAML, ALIASES], ids=["json", "yaml", "aliases"])
def test_schedules_and_inventories_are_bounded_too(text: str) -> None:
    with pytest.raises(InvalidInput):
        parse_season(text)
    with pytest.raises(InvalidInput):
        servers_settings(text, "servers inventory")
