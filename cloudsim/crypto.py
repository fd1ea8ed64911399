"""Secrets at rest: Fernet encryption with key rotation, and a column type that uses it."""

from __future__ import annotations

from typing import Any

from cryptography.fernet import Fernet, InvalidToken, MultiFernet
from flask import current_app
from sqlalchemy import Text
from sqlalchemy.types import TypeDecorator


class DecryptionError(Exception):
    """A stored secret cannot be decrypted with any configured key."""


class Keyring:
    """Encrypt with the newest key; decrypt with any configured key."""

    def __init__(self, keys: tuple[str, ...]) -> None:
        if not keys:
            raise ValueError("at least one encryption key is required")
        self._fernet = MultiFernet([Fernet(k) for k in keys])

    def __repr__(self) -> str:
        return "Keyring(<hidden>)"

    def encrypt(self, plaintext: str) -> str:
        """Return the token for plaintext under the newest key."""
        return self._fernet.encrypt(plaintext.encode()).decode()

    def decrypt(self, token: str) -> str:
        """Return the plaintext of a token made with any configured key."""
        try:
            return self._fernet.decrypt(token.encode()).decode()
        except InvalidToken:
            raise DecryptionError("stored secret does not match any encryption key") from None

    def rotate(self, token: str) -> str:
        """Re-encrypt a token under the newest key."""
        return self._fernet.rotate(token.encode()).decode()


def keyring() -> Keyring:
    """Return the keyring of the current app."""
    return current_app.extensions["cloudsim.keyring"]  # type: ignore[no-any-return]


class EncryptedText(TypeDecorator[str]):
    """A text column stored Fernet-encrypted with the app's keyring."""

    impl = Text
    cache_ok = True

    def process_bind_param(self, value: Any, dialect: Any) -> str | None:
        return None if value is None else keyring().encrypt(str(value))

    def process_result_value(self, value: Any, dialect: Any) -> str | None:
        return None if value is None else keyring().decrypt(value)
