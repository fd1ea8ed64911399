"""Another team's things and things that do not exist get the very same answer.

For every route the matrix answers 404 to team B's user on team A's objects, the same route
with ids that exist nowhere must answer with the same status and the same message (ids aside).
"""

from __future__ import annotations

import re
from pathlib import Path

from flask import Flask, url_for

from cloudsim.auth.policy import SYSTEM
from cloudsim.extensions import db
from cloudsim.jobs.service import enqueue
from cloudsim.models import Constellation, ConstellationState, Role, User
from tests.conftest import log_in, make_user, token_for
from tests.web.test_authorization_matrix import MATRIX, PERSONAS, _url

MISSING = 424242
HIDDEN = [key for key, statuses in MATRIX.items() if statuses[PERSONAS.index("user_b")] == 404]


def _message(response: object) -> tuple[int, str]:
    status = response.status_code  # type: ignore[attr-defined]
    if response.is_json:  # type: ignore[attr-defined]
        return status, response.json["message"]  # type: ignore[attr-defined]
    page = response.get_data(as_text=True)  # type: ignore[attr-defined]
    match = re.search(r'<p class="lead" role="alert">(.*?)</p>', page, re.S)
    return status, match.group(1).strip() if match else page


def _without_ids(message: str, ids: list[str]) -> str:
    for value in sorted(ids, key=len, reverse=True):
        message = re.sub(rf"\b{re.escape(value)}\b", "N", message)
    return message


def test_not_yours_reads_exactly_like_not_there(
    app: Flask, people: dict[str, User | None], tmp_path: Path
) -> None:
    assert len(HIDDEN) >= 15  # the routes the matrix hides from other teams
    app.config["WTF_CSRF_ENABLED"] = False
    team_a = people["user_a"].team  # type: ignore[union-attr]
    job_id = enqueue("diagnostics", SYSTEM, team_id=team_a.id).id
    constellation = Constellation(
        name="team-a-vrc", kind="vrc", provider="local", team_id=team_a.id
    )
    constellation.state = ConstellationState.READY
    db.session.add(constellation)
    db.session.commit()
    client = app.test_client()
    log_in(client, people["user_b"])  # type: ignore[arg-type]
    headers = token_for(people["user_b"])  # type: ignore[arg-type]
    differ = []
    for endpoint, method in HIDDEN:
        theirs = _url(app, endpoint, team_a, people["user_a"], job_id, constellation.id, tmp_path)  # type: ignore[arg-type]
        rule = next(r for r in app.url_map.iter_rules() if r.endpoint == endpoint)
        values = {name: ("no-such-job" if name == "job_id" else MISSING) for name in rule.arguments}
        with app.test_request_context():
            missing = url_for(endpoint, **values)
        answers = []
        for url in (theirs, missing):
            if url.startswith("/api/"):
                response = client.open(url, method=method, json={}, headers=headers)
            else:
                response = client.open(url, method=method)
            ids = re.findall(r"[\w-]+", url.split("?")[0])
            status, message = _message(response)
            answers.append((status, _without_ids(message, ids)))
            db.session.rollback()
        if answers[0] != answers[1]:
            differ.append(f"{method} {endpoint}: theirs {answers[0]} != missing {answers[1]}")
    assert not differ, "\n".join(differ)


def test_a_users_id_cannot_be_probed_through_the_vpn_bundle(
    app: Flask, people: dict[str, User | None]
) -> None:
    team_a = people["user_a"].team  # type: ignore[union-attr]
    constellation = Constellation(name="vpn-a", kind="vrc", provider="local", team_id=team_a.id)
    db.session.add(constellation)
    db.session.commit()
    teammate = make_user(Role.USER, team_a)
    headers = token_for(people["user_a"])  # type: ignore[arg-type]
    api = app.test_client()
    web = app.test_client()
    log_in(web, people["user_a"])  # type: ignore[arg-type]
    answers = {}
    for label, user_id in (
        ("teammate", teammate.id),
        ("other team", people["user_b"].id),  # type: ignore[union-attr]
        ("admin", people["admin"].id),  # type: ignore[union-attr]
        ("nobody", MISSING),
    ):
        path = f"/constellations/{constellation.id}/vpn-bundle?user_id={user_id}"
        for name, response in (
            ("api", api.get("/api/v1" + path, headers=headers)),
            ("web", web.get(path)),
        ):
            status, message = _message(response)
            answers[(label, name)] = (status, message.replace(str(user_id), "N"))
    for name in ("api", "web"):
        seen = {answers[(label, name)] for label in ("teammate", "other team", "admin", "nobody")}
        assert len(seen) == 1 and next(iter(seen))[0] == 404, (name, seen)
