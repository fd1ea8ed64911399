"""Kernel parameters: set now, and persisted for the next boot."""

from __future__ import annotations

import shlex
from collections.abc import Iterator, Mapping

from provisioners.remote.facts import PathFact, PathState, SysctlFact
from provisioners.remote.facts.sysctl import normalize_sysctl_value
from provisioners.remote.operations.base import Command, Operation, Step
from provisioners.remote.operations.errors import OperationError
from provisioners.remote.operations.files import plan_file_content
from provisioners.remote.operations.templates import MachineTemplates

DEFAULT_PERSIST_PATH = "/etc/sysctl.d/60-cloudsim.conf"
PERSIST_TEMPLATE = "common/sysctl-cloudsim.conf.j2"


def sysctl(
    values: Mapping[str, str | int],
    *,
    persist_path: str | None = DEFAULT_PERSIST_PATH,
    templates: MachineTemplates | None = None,
) -> Operation:
    """Ensure kernel parameters have these values now and (unless persist_path is None) at boot."""
    wanted = {key: normalize_sysctl_value(str(value)) for key, value in values.items()}
    runtime_fact = SysctlFact(tuple(sorted(wanted)))
    persisted = (
        (templates or MachineTemplates()).render(PERSIST_TEMPLATE, {"values": wanted}).encode()
        if persist_path is not None
        else None
    )

    def plan_runtime(current: dict[str, str | None]) -> Iterator[Step]:
        for key in runtime_fact.keys:
            if current[key] is None:
                raise OperationError(f"the kernel has no parameter {key}")
            if current[key] != wanted[key]:
                yield Command(f"sysctl -w {shlex.quote(f'{key}={wanted[key]}')}")

    name = "sysctl " + " ".join(f"{key}={wanted[key]}" for key in runtime_fact.keys)
    if persist_path is None or persisted is None:
        return Operation(name, (runtime_fact,), plan_runtime)

    def plan(current: dict[str, str | None], file_state: PathState) -> Iterator[Step]:
        yield from plan_runtime(current)
        yield from plan_file_content(persist_path, persisted, file_state, 0o644, None, None)

    return Operation(name, (runtime_fact, PathFact(persist_path, checksum=True)), plan)
