"""Find a named, terminable row (a constellation, a team instance) by what a user typed."""

from __future__ import annotations

from typing import Any, TypeVar

from sqlalchemy import select

from cloudsim.extensions import db
from cloudsim.web.inputs import as_id

R = TypeVar("R")


def by_id_or_name(model: type[R], ref: int | str, terminated: Any) -> R | None:
    """Return the row with id ref, else the live row named ref, else its latest terminated one.

    A name may be used again once its row is terminated, so the history keeps older rows of
    the same name. A number too big for an id is taken as a name (found nowhere), not sent to
    the database, which would refuse it with an error.
    """
    row_id = ref if isinstance(ref, int) else as_id(ref)
    if row_id is not None:
        return db.session.get(model, row_id)
    table: Any = model
    return db.session.scalar(
        select(model)
        .where(table.name == ref)
        .order_by(table.state == terminated, table.id.desc())
        .limit(1)
    )
