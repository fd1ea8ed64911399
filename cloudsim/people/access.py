"""What a person loses when they leave a team: the one place that takes their team access away.

Called when a user is moved to another team, promoted out of teams, disabled or deleted. Every
kind of access to a team's machines is revoked here, so a new kind (SSH keys per user, say)
is added in this one function and every one of those changes revokes it too.
"""

from __future__ import annotations

from cloudsim.launched_constellations.vpn import revoke_and_push
from cloudsim.models import User


def revoke_team_access(user: User) -> None:
    """Revoke the user's access to their (former) team's constellations, at once."""
    revoke_and_push(user)  # VPN certificates, and the routers' revocation lists
