"""Debian packages."""

from __future__ import annotations

import shlex
from collections.abc import Iterator, Sequence

from provisioners.remote.facts import DebPackagesFact
from provisioners.remote.operations.base import Command, Operation, Step


def deb_packages(names: Sequence[str]) -> Operation:
    """Ensure Debian packages are installed (a no-op when they already are)."""
    fact = DebPackagesFact(tuple(names))

    def plan(installed: dict[str, str | None]) -> Iterator[Step]:
        missing = [name for name in fact.names if installed.get(name) is None]
        if missing:
            yield Command(
                "DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "
                + shlex.join(missing)
            )

    return Operation(f"deb packages {' '.join(fact.names)}", (fact,), plan)
