"""Plain results of commands and file transfers."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class CommandResult:
    """What one remote command printed and how it ended."""

    stdout: str
    stderr: str
    exit_code: int
    duration: float

    @property
    def ok(self) -> bool:
        """Return whether the command exited zero."""
        return self.exit_code == 0


@dataclass(frozen=True)
class Transfer:
    """Size and checksum of a file moved; resumed_from: bytes a previous try had copied."""

    size: int
    sha256: str
    resumed_from: int = 0
