"""A fact: a small read-only command run on a machine and the parser of its output."""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Generic, TypeVar

from provisioners.remote.ssh import SSHError, SSHExecutor, SSHTarget

T = TypeVar("T")

# facts are quick reads; a machine that takes longer than this is in trouble
FACT_TIMEOUT_SECONDS = 60.0


class FactError(SSHError):
    """Raise when a fact command fails or prints something the parser does not understand."""


class Fact(ABC, Generic[T]):
    """Read one piece of a machine's current state."""

    #: exit codes that still carry a meaningful answer (e.g. 1 = "not found")
    ok_exit_codes: frozenset[int] = frozenset({0})

    @property
    @abstractmethod
    def command(self) -> str:
        """Return the shell command that prints the fact (every argument quoted)."""

    @abstractmethod
    def parse(self, stdout: str, exit_code: int) -> T:
        """Turn the command's output into the fact's value."""

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.command!r})"


def read_fact(executor: SSHExecutor, machine: SSHTarget, fact: Fact[T], *, sudo: bool = False) -> T:
    """Run a fact's command on a machine and parse what it printed."""
    result = executor.run(
        machine, fact.command, sudo=sudo, check=False, timeout=FACT_TIMEOUT_SECONDS
    )
    if result.exit_code not in fact.ok_exit_codes:
        raise FactError(
            f"{machine.name}: fact {type(fact).__name__} failed with exit {result.exit_code}: "
            f"{executor.mask(result.stderr.strip() or result.stdout.strip())}"
        )
    try:
        return fact.parse(result.stdout, result.exit_code)
    except (ValueError, IndexError) as exc:
        raise FactError(
            f"{machine.name}: fact {type(fact).__name__} printed unexpected output: {exc}"
        ) from exc
