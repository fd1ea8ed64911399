"""Memory each role's host takes on this provider, as bench/host_memory.py measured it.

A `cloudsim` host (a team's CloudSim, with its workers, database and software on its own
tmpfs layer) takes some forty times a vrc field computer: counting every host alike (160 MiB)
admitted ten times too many team CloudSims. The figures
are package data the bench rewrites (`--write`), so admission follows measurement.
"""

from __future__ import annotations

import functools
import json
import math
from dataclasses import dataclass
from importlib import resources
from typing import Any

FIGURES = "host_memory.json"


@dataclass(frozen=True)
class HostMemory:
    """MiB each role's host takes (margin included), and what an unknown role counts."""

    roles_mib: dict[str, int]
    default_mib: int

    def of(self, role: str | None) -> int:
        """Return the MiB a host of role counts."""
        return self.roles_mib.get(role or "", self.default_mib)

    def smallest(self) -> int:
        """Return the smallest host's MiB (what sizes the kernel limits for the most hosts)."""
        return min([*self.roles_mib.values(), self.default_mib])


def from_figures(figures: dict[str, Any]) -> HostMemory:
    """Return the counted figures: each measured one times the margin, rounded up."""
    margin = float(figures["margin"])
    return HostMemory(
        roles_mib={
            role: math.ceil(mib * margin) for role, mib in dict(figures["roles_mib"]).items()
        },
        default_mib=math.ceil(float(figures["default_mib"]) * margin),
    )


@functools.cache
def measured() -> HostMemory:
    """Return the figures shipped with the provider (package data: read once per process)."""
    text = resources.files(__package__).joinpath(FIGURES).read_text()
    return from_figures(json.loads(text))


def uniform(mib: int) -> HostMemory:
    """Return figures counting every host as mib (an operator's CLOUDSIM_LOCAL_HOST_MEMORY_MB)."""
    return HostMemory(roles_mib={}, default_mib=mib)
