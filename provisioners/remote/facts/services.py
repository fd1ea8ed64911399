"""Facts about services under systemd, or under plain init scripts without it."""

from __future__ import annotations

import re
import shlex
from dataclasses import dataclass
from typing import Literal

from provisioners.remote.facts.base import Fact

SERVICE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9@._:-]*$")
# `systemctl is-enabled` states that mean "starts at boot, nothing to enable"
_SYSTEMD_ENABLED_STATES = frozenset(
    {"enabled", "enabled-runtime", "static", "alias", "indirect", "generated"}
)


@dataclass(frozen=True)
class ServiceState:
    """How a service is managed and whether it starts at boot and runs now."""

    init: Literal["systemd", "sysv"]
    enabled_state: str  # systemctl is-enabled's word, or enabled/disabled for init scripts
    active: bool

    @property
    def enabled(self) -> bool:
        """Return whether the service starts at boot."""
        return self.enabled_state in _SYSTEMD_ENABLED_STATES

    @property
    def masked(self) -> bool:
        """Return whether systemd refuses to start the unit at all."""
        return self.enabled_state.startswith("masked")


@dataclass(frozen=True)
class ServiceFact(Fact[ServiceState]):
    """Read a service's init system, enablement and activity."""

    name: str

    def __post_init__(self) -> None:
        if not SERVICE_NAME.match(self.name):
            raise ValueError(f"not a service name: {self.name!r}")

    @property
    def command(self) -> str:
        """Return a probe that asks systemctl when systemd runs, else the init script."""
        name = shlex.quote(self.name)
        systemd = (
            "printf 'init=systemd\\nenabled=%s\\nactive=%s\\n' "
            f'"$(systemctl is-enabled {name} 2>/dev/null)" '
            f'"$(systemctl is-active {name} 2>/dev/null)"'
        )
        sysv = (
            "printf 'init=sysv\\nenabled=%s\\nactive=%s\\n' "
            f'"$(ls /etc/rc2.d/S??{name} >/dev/null 2>&1 && echo enabled || echo disabled)" '
            f'"$(service {name} status >/dev/null 2>&1 && echo active || echo inactive)"'
        )
        # the sd_booted() test: systemd is PID 1 exactly when this directory exists
        return f"if [ -d /run/systemd/system ]; then {systemd}; else {sysv}; fi"

    def parse(self, stdout: str, exit_code: int) -> ServiceState:
        """Parse the probe's init=, enabled= and active= lines."""
        values = dict(line.split("=", 1) for line in stdout.splitlines())
        init = values["init"]
        if init not in ("systemd", "sysv"):
            raise ValueError(f"unknown init system {init!r}")
        return ServiceState(
            init=init,  # type: ignore[arg-type]
            enabled_state=values["enabled"] or "not-found",
            active=values["active"] == "active",
        )
