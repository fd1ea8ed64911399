"""Who may do what: role checks shared by the web pages, the API and the services."""

from __future__ import annotations

from collections.abc import Callable
from functools import wraps
from typing import Any, TypeVar, cast

from flask import abort
from flask_login import current_user

from cloudsim.errors import Forbidden, NotFound
from cloudsim.extensions import login_manager
from cloudsim.models import Role, User

F = TypeVar("F", bound=Callable[..., Any])


class SystemActor:
    """CloudSim itself acting: the operator at the `cloudsim` command, beat, a job's follow-ups.

    It may do anything an admin may, belongs to no team and has no account; the audit log
    names it "system".
    """

    id: int | None = None
    email = "system"
    team_id: int | None = None
    role = Role.ADMIN

    def has_role(self, role: Role) -> bool:
        """The system has every role."""
        return True

    def __repr__(self) -> str:
        return "SYSTEM"


SYSTEM = SystemActor()
Actor = User | SystemActor  # who does something: a person, or CloudSim itself


def require_role(actor: Actor, role: Role, action: str) -> None:
    """Raise Forbidden unless the actor has `role`."""
    if not actor.has_role(role):
        raise Forbidden(f"only {role.value}s and above may {action}")


def require_team_access(actor: Actor, team_id: int | None, kind: str, ref: object) -> None:
    """Raise NotFound for another team's `kind` `ref`, worded exactly as for a missing one:
    a user must not learn what exists."""
    if actor.has_role(Role.OFFICER):
        return
    if team_id is None or actor.team_id != team_id:
        raise NotFound.of(kind, ref)


def role_required(role: Role) -> Callable[[F], F]:
    """Decorate a view so that only logged-in users with `role` or above reach it."""

    def decorator(view: F) -> F:
        @wraps(view)
        def wrapped(*args: Any, **kwargs: Any) -> Any:
            if not current_user.is_authenticated:
                return login_manager.unauthorized()
            if not current_user.has_role(role):
                abort(403)
            return view(*args, **kwargs)

        return cast(F, wrapped)

    return decorator
