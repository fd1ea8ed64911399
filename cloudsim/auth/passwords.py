"""Password hashing (Argon2id) and the password policy."""

from __future__ import annotations

import secrets

from argon2 import PasswordHasher
from argon2.exceptions import InvalidHashError, VerificationError
from flask import current_app

from cloudsim.errors import InvalidInput

MIN_LENGTH = 10


class Passwords:
    """The app's Argon2id hasher, with a dummy hash to verify against for unknown accounts."""

    def __init__(self, time_cost: int, memory_kib: int) -> None:
        self.hasher = PasswordHasher(time_cost=time_cost, memory_cost=memory_kib)
        # Verifying against this keeps a login for an unknown e-mail as slow as a known one.
        self.dummy_hash = self.hasher.hash("not-a-real-password")


def _passwords() -> Passwords:
    return current_app.extensions["cloudsim.passwords"]  # type: ignore[no-any-return]


def check_policy(password: str) -> None:
    """Raise InvalidInput when the password is too weak to accept."""
    if len(password) < MIN_LENGTH:
        raise InvalidInput(f"password must be at least {MIN_LENGTH} characters long")
    if password.strip() != password:
        raise InvalidInput("password must not start or end with spaces")


def hash_password(password: str) -> str:
    """Return the Argon2id hash of a password that passes the policy."""
    check_policy(password)
    return _passwords().hasher.hash(password)


def verify_password(password_hash: str | None, password: str) -> bool:
    """Return True when the password matches the hash (constant work for a missing hash)."""
    passwords = _passwords()
    try:
        matches = passwords.hasher.verify(password_hash or passwords.dummy_hash, password)
        return matches and password_hash is not None
    except (VerificationError, InvalidHashError):
        return False


def generate_password() -> str:
    """Return a new random password that passes the policy."""
    return secrets.token_urlsafe(15)
