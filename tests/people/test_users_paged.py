"""Users are listed a page at a time as the README says: `GET /api/v1/users` with
`?page=&page_size=` and the paging in an `X-Pagination` header, the Users page with its
**Next →** link; walking the pages lists every user exactly once, by e-mail."""

from __future__ import annotations

import json

from flask import Flask

from cloudsim.extensions import db
from cloudsim.models import Role, User
from tests.competition.test_paged_pages import follow
from tests.conftest import log_in, make_user, token_for
from tests.support.season import new_teams


def add_members(count: int) -> None:
    """Add a team with `count` members (rows only: none of them logs in)."""
    team = new_teams(1)[0]
    db.session.add_all(
        User(email=f"member-{n:03d}@example.org", team_id=team.id, password_hash="x")
        for n in range(count)
    )
    db.session.commit()


def test_users_list_walks_page_by_page(app: Flask) -> None:
    add_members(130)
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


def test_users_page_walks_page_by_page(app: Flask) -> None:
    add_members(130)
    client = app.test_client()
    log_in(client, make_user(Role.OFFICER))
    pages = follow(client, "/users", "Next →", r'<tr><td><a href="/users/\d+">([^<]+)</a>')
    assert [len(page) for page in pages] == [100, 31]
    emails = [email for page in pages for email in page]
    assert len(set(emails)) == 131 and emails == sorted(emails)
