"""The SSH and provisioning layer's one exception hierarchy."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from provisioners.remote.ssh.result import CommandResult


class SSHError(Exception):
    """Root of every error raised while reaching or provisioning a machine."""


class Interrupted(SSHError):
    """Raise when the caller said stop (its job was cancelled or stalled) between two steps."""


class ConnectError(SSHError):
    """Raise when a machine cannot be reached or authenticated within the deadline."""


class ConnectionLost(SSHError):
    """Raise when a machine's connection broke while a command ran (its result is unknown)."""


class HostKeyMismatch(SSHError):
    """Raise when a machine presents a host key other than the one recorded at first contact."""

    def __init__(self, machine_name: str, expected: str, presented: str) -> None:
        self.machine_name = machine_name
        self.expected = expected
        self.presented = presented
        super().__init__(
            f"host key of machine {machine_name!r} changed: recorded {expected}, "
            f"presented {presented} (possible man-in-the-middle, or the machine was rebuilt)"
        )


class CommandFailed(SSHError):
    """Raise when a command exits non-zero; carries the command's result."""

    def __init__(self, machine_name: str, command: str, result: CommandResult) -> None:
        self.machine_name = machine_name
        self.command = command
        self.result = result
        detail = (result.stderr or result.stdout).strip().splitlines()[-3:]
        super().__init__(
            f"{machine_name}: command exited {result.exit_code}: {command}"
            + (f" ({' / '.join(detail)})" if detail else "")
        )


class CommandTimeout(SSHError):
    """Raise when a command runs longer than its timeout (the remote process is killed)."""

    def __init__(self, machine_name: str, command: str, timeout: float) -> None:
        self.machine_name = machine_name
        self.command = command
        self.timeout = timeout
        super().__init__(f"{machine_name}: command timed out after {timeout:g} s: {command}")


class GroupError(SSHError):
    """Raise when a parallel run failed on some machines; carries every machine's outcome."""

    def __init__(self, results: Mapping[str, object]) -> None:
        self.results = dict(results)
        failed = sorted(self.failures)
        super().__init__(
            f"{len(failed)} of {len(self.results)} machines failed: "
            + "; ".join(f"{name}: {self.results[name]}" for name in failed)
        )

    @property
    def failures(self) -> dict[str, BaseException]:
        """Return the exception of each machine that failed."""
        return {
            name: outcome
            for name, outcome in self.results.items()
            if isinstance(outcome, BaseException)
        }

    @property
    def successes(self) -> dict[str, object]:
        """Return the result of each machine that succeeded."""
        return {
            name: outcome
            for name, outcome in self.results.items()
            if not isinstance(outcome, BaseException)
        }
