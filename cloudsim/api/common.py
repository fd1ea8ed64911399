"""What every API module shares: the caller, row serialisation, paging of queries."""

from __future__ import annotations

from typing import Any

import flask_smorest
from flask import Request, g
from flask_smorest import Page
from sqlalchemy import Select, func, select
from webargs import core
from webargs.flaskparser import FlaskParser, is_json_request

from cloudsim.auth.policy import require_role
from cloudsim.extensions import db
from cloudsim.models import Role, User
from cloudsim.web.inputs import INT64_MAX


class BodyParser(FlaskParser):
    """webargs, reading JSON bodies through the app's bounded parser (cloudsim.web.inputs)."""

    def _raw_load_json(self, req: Request) -> Any:
        if not is_json_request(req):
            return core.missing
        return req.get_json(force=True)  # refusals answer 400 with the reason


class Blueprint(flask_smorest.Blueprint):  # type: ignore[misc]
    """An API blueprint whose arguments are parsed by BodyParser."""

    ARGUMENTS_PARSER = BodyParser()
    PAGINATION_ARGUMENTS_PARSER = BodyParser()


def caller() -> User:
    """Return the user the request's token belongs to."""
    return g.api_user  # type: ignore[no-any-return]


def caller_with(role: Role, action: str) -> User:
    """Return the caller after checking it has `role`."""
    user = caller()
    require_role(user, role, action)
    return user


def columns(row: object) -> dict[str, Any]:
    """Return a row's column values, for answers that add a field the model does not have."""
    return {c.key: getattr(row, c.key) for c in row.__table__.columns}  # type: ignore[attr-defined]


class SelectPage(Page):  # type: ignore[misc]
    """Page through an SQLAlchemy select without loading the whole result."""

    @property
    def items(self) -> list[Any]:
        params = self.page_params
        if params.first_item > INT64_MAX:  # a page far past the end: nothing, not an overflow
            return []
        return list(
            db.session.scalars(self.collection.offset(params.first_item).limit(params.page_size))
        )

    @property
    def item_count(self) -> int:
        query: Select[Any] = self.collection
        return db.session.scalar(select(func.count()).select_from(query.order_by(None).subquery()))  # type: ignore[return-value]
