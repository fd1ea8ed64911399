"""Noting a token's use never makes a read wait for, or fail on, another writer."""

from __future__ import annotations

import sqlite3
from datetime import timedelta

from flask import Flask

from cloudsim.extensions import db
from cloudsim.models import ApiToken, Role, utcnow
from tests.conftest import make_user, token_for


def test_an_api_read_answers_while_another_transaction_holds_the_write_lock(app: Flask) -> None:
    admin = make_user(Role.ADMIN)
    headers = token_for(admin)
    token = db.session.scalars(db.select(ApiToken)).one()
    token.last_used_at = utcnow() - timedelta(hours=1)  # due to be noted again
    db.session.commit()
    path = db.engine.url.database
    assert path
    holder = sqlite3.connect(path, timeout=0)
    try:
        holder.execute("BEGIN IMMEDIATE")  # a job's write transaction, held
        response = app.test_client().get("/api/v1/teams", headers=headers)
        assert response.status_code == 200, response.get_data(as_text=True)
    finally:
        holder.rollback()
        holder.close()
    # with the lock gone, the next read notes the use
    app.test_client().get("/api/v1/teams", headers=headers)
    db.session.expire_all()
    noted = db.session.get(ApiToken, token.id)
    assert noted is not None and noted.last_used_at is not None
    assert utcnow() - noted.last_used_at < timedelta(minutes=1)
