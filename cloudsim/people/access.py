"""What a person loses when they leave a team: the one place that takes their team access away.

Called when a user is moved to another team, promoted out of teams, disabled or deleted. Every
kind of access to a team's machines is revoked here, so a new kind (SSH keys per user, say)
is added in this one function and every one of those changes revokes it too.
"""

from __future__ import annotations

from collections.abc import Callable

from cloudsim.launched_constellations.access import refresh_team_access
from cloudsim.launched_constellations.vpn import revoke_and_push, revoke_user
from cloudsim.models import User


def revoke_team_access(user: User, old_team_id: int | None = None) -> None:
    """Push the user's team access at once: their VPN certificates revoked where they no
    longer belong, and the SSH keys of the old and the new team's field computers rewritten
    (a user enabled again, or moved in, gets their keys there too)."""
    revoke_and_push(user, [old_team_id])


def revoke_before_delete(user: User) -> Callable[[], None]:
    """Revoke everything of a user about to be deleted; return what to call once the deletion
    is committed (the refresh that rewrites their team's keys without theirs)."""
    team_id = user.team_id
    revoked = revoke_user(user)
    return lambda: refresh_team_access([team_id], also=revoked)
