"""The master's own account on a team instance: what no one on the instance may take away,
and how it is given back when it was lost anyway (a restored database, a revoked token).

A CloudSim started with CLOUDSIM_ADMIN_TOKEN is a team instance: its master installed it and
calls it with that token, which belongs to the admin CLOUDSIM_ADMIN_EMAIL. That account may
not be disabled, demoted, moved or deleted here, nor that token revoked, by anyone (page,
API or `cloudsim` command): the master alone decides what the instance holds.
"""

from __future__ import annotations

import hashlib
import time

import redis
from flask import current_app, has_app_context
from sqlalchemy import select

from cloudsim.audit.service import record
from cloudsim.auth.passwords import generate_password, hash_password
from cloudsim.auth.policy import SYSTEM
from cloudsim.config import Config
from cloudsim.errors import Conflict, InvalidInput, Unavailable
from cloudsim.extensions import db
from cloudsim.models import ApiToken, Role, User


def _config() -> Config | None:
    return current_app.config["CLOUDSIM"] if has_app_context() else None


def master_email() -> str | None:
    """Return the e-mail of the master's account here, or None when this is no team instance."""
    config = _config()
    if config is None or not config.admin_token:
        return None
    return config.admin_email.strip().lower()


def is_master_account(user: User) -> bool:
    """Return whether the user is the account this instance's master calls it with."""
    email = master_email()
    return email is not None and user.email == email


def refuse_for_master_account(user: User, what: str) -> None:
    """Raise Conflict (409, with why) when `what` would take the master's account away."""
    if is_master_account(user):
        raise Conflict(
            f"{user.email} is the account this instance's master manages it with: it cannot be "
            f"{what} here (restore it from the master with `cloudsim instance restore-access`)"
        )


def is_master_token(token: ApiToken) -> bool:
    """Return whether the token is the one the master calls this instance with."""
    config = _config()
    if config is None or not config.admin_token:
        return False
    return token.token_hash == hashlib.sha256(config.admin_token.encode()).hexdigest()


def restore_master_access(email: str, plaintext: str) -> list[str]:
    """Make the admin `email` exist, active, an admin, with a live token of this plaintext;
    return what had to be put back (nothing: it was whole)."""
    email = email.strip().lower()
    digest = hashlib.sha256(plaintext.encode()).hexdigest()
    restored: list[str] = []
    user = db.session.scalar(select(User).where(User.email == email))
    if user is None:
        # a restored database without it: a fresh password (the master uses the token)
        password_hash = hash_password(generate_password())
        user = User(email=email, name="Admin", role=Role.ADMIN, password_hash=password_hash)
        db.session.add(user)
        restored.append(f"account {email} created")
    if user.role != Role.ADMIN or user.team_id is not None:
        user.role, user.team_id = Role.ADMIN, None
        restored.append(f"account {email} made an admin again")
    if not user.active:
        user.active = True
        restored.append(f"account {email} enabled")
    db.session.flush()
    token = db.session.scalar(select(ApiToken).where(ApiToken.token_hash == digest))
    if token is None:
        token = ApiToken(user=user, name="master", prefix=plaintext[:10], token_hash=digest)
        db.session.add(token)
        restored.append("the master's token issued")
    else:
        if token.user_id != user.id:
            token.user = user
            restored.append("the master's token given back to its account")
        if token.revoked_at is not None:
            token.revoked_at = None
            restored.append("the master's token un-revoked")
    db.session.flush()
    if restored:
        record(
            "master.restore",
            SYSTEM,
            target_type="user",
            target_id=user.id,
            email=email,
            restored=restored,
        )
    return restored


def restore_configured_access() -> list[str]:
    """Restore the master's access from this CloudSim's own settings (a team instance's)."""
    config = _config()
    if config is None or not config.admin_token:
        raise InvalidInput("CLOUDSIM_ADMIN_TOKEN is not set: this CloudSim is no team instance")
    return restore_master_access(config.admin_email, config.admin_token)


# Until a restarted instance has heard from its master, its accounts may be old (a user the
# master disabled while it was down): it serves no login but the master's until then.
STARTED_KEY = "cloudsim:instance:started"
SYNCED_KEY = "cloudsim:instance:synced"
_current_since: set[str] = set()  # per process: the start seen followed by a sync


def _redis(config: Config) -> redis.Redis:
    return redis.Redis.from_url(config.effective_redis_url, decode_responses=True, socket_timeout=2)


def note_started(config: Config) -> None:
    """Note that this instance starts: logins wait for the master's next desired state."""
    if config.admin_token:
        _redis(config).set(STARTED_KEY, f"{time.time():.6f}")


def note_synced() -> None:
    """Note that this instance now has its master's current accounts."""
    config = _config()
    if config is not None and config.admin_token:
        _redis(config).set(SYNCED_KEY, f"{time.time():.6f}")


def awaiting_master() -> bool:
    """Return whether this instance started and has not had its master's accounts since."""
    config = _config()
    if config is None or not config.admin_token:
        return False
    try:
        started, synced = (
            None if v is None else str(v) for v in _redis(config).mget(STARTED_KEY, SYNCED_KEY)
        )
    except redis.RedisError:
        return True  # cannot tell: the safe side
    if started is None or started in _current_since:
        return False
    if synced is not None and float(synced) >= float(started):
        _current_since.add(started)
        return False
    return True


WAITING_MESSAGE = (
    "This team instance has just started and has not heard from its master yet: logins "
    "open as soon as it has the master's current accounts (usually within seconds)."
)


def refuse_until_current(user: User | None) -> None:
    """Raise Unavailable (503, why) for anyone but the master while the instance waits for it."""
    if (user is None or not is_master_account(user)) and awaiting_master():
        raise Unavailable(WAITING_MESSAGE)
