"""Real Chromium: an officer moves a user to another team and disables them from the Users page;
the user's open session ends; the page refuses what the rules refuse."""

from __future__ import annotations

import pytest
from flask import Flask
from playwright.sync_api import Browser, Page, expect

from cloudsim.extensions import db
from cloudsim.models import User
from tests.web.test_browser import browser, live_url, log_in_page  # noqa: F401

pytestmark = pytest.mark.browser


def _row(page: Page, email: str) -> list[str]:
    row = page.get_by_role("row").filter(has=page.get_by_role("link", name=email))
    return [cell.strip() for cell in row.get_by_role("cell").all_inner_texts()]


def test_an_officer_moves_and_disables_a_user_from_the_users_page(
    app: Flask,
    live_url: str,  # noqa: F811
    browser: Browser,  # noqa: F811
    people: dict[str, User | None],
) -> None:
    user, officer, admin = people["user_a"], people["officer"], people["admin"]
    assert user is not None and officer is not None and admin is not None
    team_b = people["user_b"].team  # type: ignore[union-attr]
    victim = browser.new_context().new_page()
    log_in_page(victim, live_url, user)
    expect(victim.get_by_role("link", name="My team")).to_be_visible()

    page = browser.new_context().new_page()
    log_in_page(page, live_url, officer)
    page.get_by_role("navigation", name="Main").get_by_role("link", name="Users").click()
    page.get_by_role("link", name=user.email).click()
    page.get_by_label("Team").select_option(label=team_b.name)  # type: ignore[union-attr]
    page.get_by_label("Active").uncheck()
    page.get_by_role("button", name="Save").click()
    expect(page.get_by_text(f"Saved {user.email}.")).to_be_visible()
    assert _row(page, user.email)[2:5] == ["user", team_b.name, "no"]  # type: ignore[union-attr]
    db.session.expire_all()
    saved = db.session.get(User, user.id)
    assert saved is not None and (saved.team_id, saved.active) == (team_b.id, False)  # type: ignore[union-attr]

    victim.reload()  # the disabled user's open session ended on the server
    expect(victim.get_by_role("button", name="Log in")).to_be_visible()

    page.get_by_role("link", name=user.email).click()
    page.get_by_label("Active").check()
    page.get_by_role("button", name="Save").click()
    expect(page.get_by_text(f"Saved {user.email}.")).to_be_visible()
    assert _row(page, user.email)[2:5] == ["user", team_b.name, "yes"]  # type: ignore[union-attr]

    # An admin cannot demote themselves (nor, so, the last admin): the page says why.
    admin_page = browser.new_context().new_page()
    log_in_page(admin_page, live_url, admin)
    admin_page.goto(f"{live_url}/users/{admin.id}")
    admin_page.get_by_label("Role").select_option("officer")
    admin_page.get_by_role("button", name="Save").click()
    expect(admin_page.get_by_role("alert")).to_contain_text("cannot change your own role")
    db.session.expire_all()
    assert db.session.get(User, admin.id).role.value == "admin"  # type: ignore[union-attr]
    for context in (victim.context, page.context, admin_page.context):
        context.close()
