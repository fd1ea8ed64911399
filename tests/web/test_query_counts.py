"""No page or API list makes more database queries when there are more rows (no N+1).

Every GET route a team user, an officer or an admin may open (status 200 in the authorization
matrix) is visited on a small season and again on one three times its size; each must make
exactly as many queries both times. A new GET route is covered without an entry here.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from datetime import timedelta
from typing import Any

from flask import Flask, current_app
from flask.testing import FlaskClient
from sqlalchemy import event

from cloudsim.competition.artifacts import LogStore
from cloudsim.extensions import db
from cloudsim.models import (
    Constellation,
    Machine,
    Phase,
    Role,
    Team,
    TeamInstance,
    User,
    utcnow,
)
from tests.conftest import log_in, make_user, token_for
from tests.support.season import add_credentials, add_season, new_teams, team_urls
from tests.web.test_authorization_matrix import MATRIX, PERSONAS

VISITORS = ("user_a", "officer", "admin")


@contextmanager
def counting() -> Iterator[list[str]]:
    """Collect the SQL statements the app sends while the block runs."""
    statements: list[str] = []

    def collect(*args: Any) -> None:
        statements.append(args[2])

    event.listen(db.engine, "before_cursor_execute", collect)
    try:
        yield statements
    finally:
        event.remove(db.engine, "before_cursor_execute", collect)


def grow(team_a: Team, others: list[Team], people: dict[str, User], scale: int) -> None:
    """Add a season of `scale` rows per team (and per visitor's own lists), `scale` new teams."""
    teams = [team_a, *others, *new_teams(scale)]
    store = LogStore(current_app.config["CLOUDSIM"])
    add_season(store, teams, "x", users=scale, runs=scale, jobs=scale, events=4 * scale)
    for user in people.values():
        add_credentials(user, scale)
    previous = None
    # phases, each entered through the one before: the newest always has an entry phase
    for n in range(scale + 1):
        previous = Phase(
            name=f"phase-{scale}-{n}",
            window_start=utcnow(),
            window_stop=utcnow() + timedelta(hours=1),
            worlds=[["vrc_task_1", 1]],
            uplink_bits=1,
            downlink_bits=1,
            entry_phase=previous,
            entry_min_score=None if previous is None else 1,
        )
        db.session.add(previous)
    for n in range(scale):  # team instances (admins' page and list), with their machines
        constellation = Constellation(name=f"ti-{scale}-{n}", kind="cloudsim", provider="local")
        constellation.machines.append(Machine(name="server", role="cloudsim"))
        db.session.add(
            TeamInstance(name=constellation.name, team=teams[n], constellation=constellation)
        )
    db.session.commit()
    others[:] = teams[1:]


def urls(app: Flask, team_a: Team) -> dict[tuple[str, str], str]:
    """Return (persona, endpoint) -> URL of every GET route each visitor may open."""
    gets = {endpoint for endpoint, method in MATRIX if method == "GET"}
    found = team_urls(app, team_a.id, gets)
    opened = {e for e in gets for p in VISITORS if MATRIX[(e, "GET")][PERSONAS.index(p)] == 200}
    assert opened <= found.keys(), f"no URL for {opened - found.keys()}: seed what they show"
    return {
        (persona, endpoint): url
        for endpoint, url in found.items()
        for persona in VISITORS
        if MATRIX[(endpoint, "GET")][PERSONAS.index(persona)] == 200
    }


def visit_all(
    clients: dict[str, FlaskClient], headers: dict[str, dict[str, str]], urls: dict[Any, str]
) -> dict[tuple[str, str], int]:
    """Visit every URL as its persona; return the queries each made (answers must be 200)."""
    counts = {}
    for (persona, endpoint), url in sorted(urls.items()):
        extra = headers[persona] if url.startswith("/api/") else {}
        with counting() as statements:
            response = clients[persona].get(url, headers=extra)
            response.get_data()  # a streamed answer queries while it is read
        assert response.status_code == 200, f"{persona} {url}: {response.status_code}"
        counts[(persona, endpoint)] = len(statements)
    return counts


def test_no_page_or_api_list_makes_more_queries_for_more_rows(any_db_app: Flask) -> None:
    team_a = new_teams(1)[0]
    people = {
        "user_a": make_user(Role.USER, team_a),
        "officer": make_user(Role.OFFICER),
        "admin": make_user(Role.ADMIN),
    }
    others: list[Team] = []
    grow(team_a, others, people, 1)
    clients = {}
    for persona, user in people.items():
        clients[persona] = any_db_app.test_client()
        log_in(clients[persona], user)
    headers = {persona: token_for(user) for persona, user in people.items()}
    visit_all(clients, headers, urls(any_db_app, team_a))  # caches warm: count from here
    small = visit_all(clients, headers, urls(any_db_app, team_a))
    grow(team_a, others, people, 2)
    large = visit_all(clients, headers, urls(any_db_app, team_a))
    grown = {
        f"{persona} {endpoint}": f"{small[(persona, endpoint)]} -> {count}"
        for (persona, endpoint), count in large.items()
        if count != small[(persona, endpoint)]
    }
    assert not grown, f"query counts grew with the rows: {grown}"
