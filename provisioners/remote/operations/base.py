"""Operations: desired state + current facts -> the steps that close the difference."""

from __future__ import annotations

import hashlib
import secrets
import shlex
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import PurePosixPath
from typing import Any

from provisioners.remote.facts import Fact, read_fact
from provisioners.remote.ssh import CommandFailed, SSHExecutor, SSHTarget

# commands of operations (package installs included) get this long by default
COMMAND_TIMEOUT_SECONDS = 900.0


@dataclass(frozen=True)
class Command:
    """A shell command to run on the machine (its arguments already quoted)."""

    text: str

    def describe(self) -> str:
        """Return the command as it appears in results and logs."""
        return self.text


@dataclass(frozen=True)
class Upload:
    """File content to place at a path, atomically, with mode and (optional) ownership."""

    destination: str
    content: bytes = field(repr=False)
    mode: int = 0o644
    owner: str | None = None
    group: str | None = None

    @property
    def sha256(self) -> str:
        """Return the hex SHA-256 of the content."""
        return hashlib.sha256(self.content).hexdigest()

    def describe(self) -> str:
        """Return a one-line summary (never the content, which may be secret)."""
        owner = f" owner {chown_spec(self.owner, self.group)}" if self.owner or self.group else ""
        return (
            f"upload {len(self.content)} bytes sha256:{self.sha256[:16]} to "
            f"{self.destination} mode {self.mode:04o}{owner}"
        )


Step = Command | Upload


@dataclass(frozen=True)
class Operation:
    """A named desired state: the facts it reads and the plan that turns them into steps."""

    name: str
    facts: tuple[Fact[Any], ...]
    plan: Callable[..., Iterable[Step]]

    def steps(self, *fact_values: Any) -> list[Step]:
        """Return the steps for the given fact values (empty = already in the desired state)."""
        return list(self.plan(*fact_values))


@dataclass(frozen=True)
class OperationResult:
    """What applying an operation did."""

    name: str
    changed: bool
    commands: list[str]


def chown_spec(owner: str | None, group: str | None) -> str:
    """Return chown's OWNER[:GROUP] or :GROUP argument."""
    if owner is None and group is None:
        raise ValueError("chown needs an owner or a group")
    return f"{owner or ''}:{group}" if group is not None else str(owner)


def plan_on(
    executor: SSHExecutor, machine: SSHTarget, operation: Operation, *, sudo: bool = False
) -> list[Step]:
    """Read an operation's facts on a machine and return its steps without running them."""
    values = [read_fact(executor, machine, fact, sudo=sudo) for fact in operation.facts]
    return operation.steps(*values)


def apply(
    executor: SSHExecutor, machine: SSHTarget, operation: Operation, *, sudo: bool = False
) -> OperationResult:
    """Bring a machine to an operation's desired state, changing only what differs."""
    steps = plan_on(executor, machine, operation, sudo=sudo)
    executed: list[str] = []
    for step in steps:
        if isinstance(step, Upload):
            executed.extend(_upload(executor, machine, step, sudo=sudo))
        else:
            executor.run(machine, step.text, sudo=sudo, timeout=COMMAND_TIMEOUT_SECONDS)
            executed.append(step.text)
    verdict = "changed" if steps else "already in the desired state"
    executor.log(machine.name, f"[{operation.name}] {verdict}")
    return OperationResult(name=operation.name, changed=bool(steps), commands=executed)


def _upload(executor: SSHExecutor, machine: SSHTarget, upload: Upload, *, sudo: bool) -> list[str]:
    destination = PurePosixPath(upload.destination)
    token = secrets.token_hex(6)
    # next to the destination the final mv is an atomic rename; a non-root login that
    # needs sudo can only write to /tmp, and mv then copies across file systems
    staging = (
        f"/tmp/.cloudsim-upload-{token}"  # noqa: S108 - unique name, moved away at once
        if sudo
        else str(destination.with_name(f".{destination.name}.cloudsim-{token}"))
    )
    executor.put_file(machine, upload.content, staging, mode=upload.mode)
    quoted_staging = shlex.quote(staging)
    finish = [f"mv -f {quoted_staging} {shlex.quote(upload.destination)}"]
    owner, group = upload.owner, upload.group
    if sudo and owner is None and group is None:
        # the staged file belongs to the login user; what sudo installs belongs to root
        owner, group = "root", "root"
    if owner is not None or group is not None:
        finish.insert(0, f"chown {shlex.quote(chown_spec(owner, group))} {quoted_staging}")
    command = " && ".join(finish)
    try:
        executor.run(machine, command, sudo=sudo, timeout=COMMAND_TIMEOUT_SECONDS)
    except CommandFailed:
        executor.run(machine, f"rm -f {quoted_staging}", sudo=sudo, check=False)
        raise
    return [upload.describe(), command]
