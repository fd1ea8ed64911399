"""Trust-on-first-use host key checking through a pluggable store."""

from __future__ import annotations

import base64
import hashlib
import threading
from collections.abc import Callable
from typing import Protocol

import paramiko

from provisioners.remote.ssh.errors import HostKeyMismatch


class HostKeyStore(Protocol):
    """Where each machine's host key is kept, as "key-type base64"."""

    def get(self, machine_name: str) -> str | None:
        """Return the recorded host key of a machine, or None before first contact."""
        ...

    def put(self, machine_name: str, key_type_and_base64: str) -> None:
        """Record a machine's host key."""
        ...


class HostKeys:
    """The host key store: keys seen in this process, backed by where the caller keeps them.

    `lookup` finds a key recorded (or pinned) elsewhere, `record` keeps a new one there (a
    database row, a provider's state file); without them the keys live as long as the
    process (tests, one-off tools). Safe to use from many threads.
    """

    def __init__(
        self,
        lookup: Callable[[str], str | None] | None = None,
        record: Callable[[str, str], None] | None = None,
    ) -> None:
        self._keys: dict[str, str] = {}
        self._lookup = lookup
        self._record = record
        self._lock = threading.Lock()

    def get(self, machine_name: str) -> str | None:
        """Return the recorded host key of a machine, or None before first contact."""
        with self._lock:
            known = self._keys.get(machine_name)
        if known is None and self._lookup is not None:
            known = self._lookup(machine_name)
        return known

    def put(self, machine_name: str, key_type_and_base64: str) -> None:
        """Record a machine's host key."""
        with self._lock:
            self._keys[machine_name] = key_type_and_base64
        if self._record is not None:
            self._record(machine_name, key_type_and_base64)


def fingerprint(key_type_and_base64: str) -> str:
    """Return the OpenSSH-style SHA256 fingerprint of a "key-type base64" host key."""
    key_type, _, blob = key_type_and_base64.partition(" ")
    digest = hashlib.sha256(base64.b64decode(blob)).digest()
    return f"{key_type} SHA256:{base64.b64encode(digest).decode().rstrip('=')}"


class TrustOnFirstUse(paramiko.MissingHostKeyPolicy):
    """Record a machine's host key at first contact and insist on it afterwards."""

    def __init__(self, store: HostKeyStore, machine_name: str, log: Callable[[str], None]) -> None:
        self._store = store
        self._machine_name = machine_name
        self._log = log

    def missing_host_key(
        self, client: paramiko.SSHClient, hostname: str, key: paramiko.PKey
    ) -> None:
        """Accept and record an unknown machine's key, or reject a changed one."""
        presented = f"{key.get_name()} {key.get_base64()}"
        recorded = self._store.get(self._machine_name)
        if recorded is None:
            self._store.put(self._machine_name, presented)
            self._log(f"recorded host key {fingerprint(presented)}")
            return
        if recorded.split()[:2] != presented.split():
            raise HostKeyMismatch(self._machine_name, fingerprint(recorded), fingerprint(presented))
