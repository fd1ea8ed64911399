"""The caller's own account: what a user may change about themselves."""

from __future__ import annotations

from cloudsim.audit.service import record
from cloudsim.auth.passwords import hash_password
from cloudsim.auth.session import end_sessions
from cloudsim.models import User


def change_own_password(user: User, new_password: str) -> None:
    """Set a user's password (the caller checked the current one); it ends their other sessions."""
    user.password_hash = hash_password(new_password)
    end_sessions(user)  # every browser session; the caller starts a new one for this browser
    record(
        "auth.password_change", user, target_type="user", target_id=user.id, team_id=user.team_id
    )
