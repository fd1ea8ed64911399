"""Per-user API tokens: shown once, stored as SHA-256, revocable."""

from __future__ import annotations

import hashlib
import secrets
from dataclasses import dataclass
from datetime import timedelta

from sqlalchemy import select, update
from sqlalchemy.orm import joinedload
from sqlalchemy.orm.attributes import set_committed_value

from cloudsim.audit.service import record
from cloudsim.auth.master import is_master_token
from cloudsim.busy import try_write
from cloudsim.errors import Conflict, InvalidInput, NotFound
from cloudsim.extensions import db
from cloudsim.models import ApiToken, User, utcnow

TOKEN_PREFIX = "cst_"  # noqa: S105 (a marker, not a secret)
MAX_ACTIVE_TOKENS = 20
USE_NOTED_EVERY = timedelta(minutes=1)  # how finely a token's last use is kept


@dataclass
class IssuedToken:
    """A new token row and its plaintext, which is never stored."""

    token: ApiToken
    plaintext: str


def _digest(plaintext: str) -> str:
    return hashlib.sha256(plaintext.encode()).hexdigest()


def issue_token(user: User, name: str) -> IssuedToken:
    """Create a token for the user; the plaintext is returned this once only."""
    name = " ".join(name.split())
    if not name or len(name) > 80:
        raise InvalidInput("token name must be 1 to 80 characters")
    active = [t for t in user.tokens if t.revoked_at is None]
    if len(active) >= MAX_ACTIVE_TOKENS:
        raise InvalidInput(f"at most {MAX_ACTIVE_TOKENS} active tokens; revoke one first")
    plaintext = TOKEN_PREFIX + secrets.token_urlsafe(32)
    token = ApiToken(user=user, name=name, prefix=plaintext[:10], token_hash=_digest(plaintext))
    db.session.add(token)
    db.session.flush()
    record(
        "token.create",
        user,
        target_type="token",
        target_id=token.id,
        team_id=user.team_id,
        name=name,
    )
    return IssuedToken(token, plaintext)


def revoke_token(user: User, token_id: int) -> None:
    """Revoke one of the user's own tokens."""
    token = db.session.get(ApiToken, token_id)
    if token is None or token.user_id != user.id:
        raise NotFound.of("token", token_id)
    if is_master_token(token):
        raise Conflict(
            "this is the token this instance's master calls it with: it cannot be revoked here"
        )
    if token.revoked_at is None:
        token.revoked_at = utcnow()
        record("token.revoke", user, target_type="token", target_id=token.id, team_id=user.team_id)


def revoke_all_tokens(user: User) -> None:
    """Revoke every live token of the user (the caller commits)."""
    now = utcnow()
    for token in user.tokens:
        if token.revoked_at is None:
            token.revoked_at = now


def user_for_token(plaintext: str) -> User | None:
    """Return the active user a live token belongs to, noting its use."""
    if not plaintext.startswith(TOKEN_PREFIX):
        return None
    token = db.session.scalar(
        select(ApiToken)
        .options(joinedload(ApiToken.user))
        .where(ApiToken.token_hash == _digest(plaintext))
    )
    if token is None or token.revoked_at is not None or not token.user.active:
        return None
    now = utcnow()
    # Noting every use would make every API read a database write (SQLite serialises them
    # all): "last used" to the minute is what the account page needs.
    if token.last_used_at is None or now - token.last_used_at >= USE_NOTED_EVERY:
        # Bookkeeping on its own short connection, skipped when the database is busy: a read
        # must never wait for (or fail on) another transaction's write lock.
        noted = update(ApiToken).where(ApiToken.id == token.id).values(last_used_at=now)
        if try_write(db.engine, noted):
            set_committed_value(token, "last_used_at", now)
    return token.user
