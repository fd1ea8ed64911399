"""Run commands on the test's hosts over SSH, through their proxy commands."""

from __future__ import annotations

from collections.abc import Sequence

from provisioners.remote.ssh import (
    CommandResult,
    ConnectError,
    ConnectPolicy,
    HostKeys,
    SSHExecutor,
    SSHTarget,
)

from .keys import KeyPair


class Shell:
    """SSH sessions to hosts, one per (host, key), recording host keys at first contact."""

    def __init__(self) -> None:
        self._host_keys = HostKeys()
        self._executor = SSHExecutor(self._host_keys, connect_policy=ConnectPolicy(deadline=30))
        # Logging in with a key that must no longer work: give up quickly.
        self._refused = SSHExecutor(self._host_keys, connect_policy=ConnectPolicy(deadline=2))

    def run(self, host: str, proxy: Sequence[str], key: KeyPair, command: str) -> CommandResult:
        """Run a command as root on host with key; return its result (any exit status)."""
        return self._executor.run(self._machine(host, proxy, key), command, check=False)

    def check(self, host: str, proxy: Sequence[str], key: KeyPair, command: str) -> str:
        """Run a command that must succeed; return its stdout."""
        return self._executor.run(self._machine(host, proxy, key), command).stdout

    def can_log_in(self, host: str, proxy: Sequence[str], key: KeyPair) -> bool:
        """Return whether key logs in to host as root."""
        try:
            self._refused.run(self._machine(host, proxy, key), "true")
        except ConnectError:
            return False
        finally:
            self._refused.close()
        return True

    def close(self) -> None:
        """Close every connection."""
        self._executor.close()
        self._refused.close()

    def _machine(self, host: str, proxy: Sequence[str], key: KeyPair) -> SSHTarget:
        return SSHTarget(
            name=f"{host}/{key.blob[-12:]}",
            host=host,
            private_key=key.private,
            proxy_command=list(proxy),
        )
