"""`GET /api/v1/users` is paged as the README says of every list: `?page=&page_size=`, the
paging in an `X-Pagination` header; walking the pages lists every user exactly once."""

from __future__ import annotations

import json

from flask import Flask

from cloudsim.extensions import db
from cloudsim.models import Role, User
from tests.conftest import make_user, token_for
from tests.support.season import new_teams


def test_users_list_walks_page_by_page(app: Flask) -> None:
    team = new_teams(1)[0]
    db.session.add_all(
        User(email=f"paged{n:03d}@example.org", team_id=team.id, password_hash="x")
        for n in range(130)
    )
    db.session.commit()
    headers = token_for(make_user(Role.OFFICER))
    client = app.test_client()

    first = client.get("/api/v1/users", headers=headers)
    assert first.status_code == 200 and len(first.json) == 100  # the default page size
    assert json.loads(first.headers["X-Pagination"])["total"] == 131

    seen: list[str] = []
    page: int | None = 1
    while page:
        answer = client.get(f"/api/v1/users?page={page}&page_size=40", headers=headers)
        assert answer.status_code == 200
        seen += [user["email"] for user in answer.json]
        page = json.loads(answer.headers["X-Pagination"]).get("next_page")
    assert len(seen) == len(set(seen)) == 131
    assert seen == sorted(seen)  # by e-mail
