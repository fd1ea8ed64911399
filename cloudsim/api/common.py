"""What every API module shares: the caller, the blueprint class, paging of queries."""

from __future__ import annotations

from typing import Any

from flask import g
from flask_smorest import Blueprint, Page
from sqlalchemy import Select, func, select
from webargs.flaskparser import FlaskParser

from cloudsim.auth.policy import require_role
from cloudsim.extensions import db
from cloudsim.models import Role, User


class _Parser(FlaskParser):
    # Bad input is a 400 with the field errors, like every other bad request.
    DEFAULT_VALIDATION_STATUS = 400


class ApiBlueprint(Blueprint):
    """A flask-smorest blueprint whose validation errors answer 400."""

    ARGUMENTS_PARSER = _Parser()


def caller() -> User:
    """Return the user the request's token belongs to."""
    return g.api_user  # type: ignore[no-any-return]


def caller_with(role: Role, action: str) -> User:
    """Return the caller after checking it has `role`."""
    user = caller()
    require_role(user, role, action)
    return user


class SelectPage(Page):  # type: ignore[misc]
    """Page through an SQLAlchemy select without loading the whole result."""

    @property
    def items(self) -> list[Any]:
        params = self.page_params
        return list(
            db.session.scalars(self.collection.offset(params.first_item).limit(params.page_size))
        )

    @property
    def item_count(self) -> int:
        query: Select[Any] = self.collection
        return db.session.scalar(select(func.count()).select_from(query.order_by(None).subquery()))  # type: ignore[return-value]
