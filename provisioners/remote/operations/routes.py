"""Routing: the default route through a gateway."""

from __future__ import annotations

import ipaddress
import shlex
from collections.abc import Iterator

from provisioners.remote.facts.routes import DefaultRouteFact
from provisioners.remote.operations.base import Command, Operation, Step


def default_route(gateway: str) -> Operation:
    """Ensure the default IPv4 route goes through gateway."""
    address = str(ipaddress.IPv4Address(gateway))

    def plan(current: str | None) -> Iterator[Step]:
        if current != address:
            yield Command(f"ip -4 route replace default via {shlex.quote(address)}")

    return Operation(f"default route via {address}", (DefaultRouteFact(),), plan)
