"""Services: enabled at boot and running, under systemd or plain init scripts."""

from __future__ import annotations

import shlex
from collections.abc import Iterator

from provisioners.remote.facts import ServiceFact, ServiceState
from provisioners.remote.operations.base import Command, Operation, Step


def service(name: str, *, running: bool | None = True, enabled: bool | None = True) -> Operation:
    """Ensure a service runs (or not) and starts at boot (or not); None = leave as is."""
    fact = ServiceFact(name)
    quoted = shlex.quote(name)

    def plan(state: ServiceState) -> Iterator[Step]:
        if state.init == "systemd":
            if (enabled or running) and state.masked:
                yield Command(f"systemctl unmask {quoted}")
            if enabled is not None and state.enabled != enabled:
                yield Command(f"systemctl {'enable' if enabled else 'disable'} {quoted}")
            if running is not None and state.active != running:
                yield Command(f"systemctl {'start' if running else 'stop'} {quoted}")
            return
        if enabled is not None and state.enabled != enabled:
            yield Command(f"update-rc.d {quoted} {'defaults' if enabled else 'disable'}")
        if running is not None and state.active != running:
            yield Command(f"service {quoted} {'start' if running else 'stop'}")

    wanted = [
        word
        for flag, word in (
            (running, "running" if running else "stopped"),
            (enabled, "enabled" if enabled else "disabled"),
        )
        if flag is not None
    ]
    return Operation(f"service {name} ({', '.join(wanted)})", (fact,), plan)
