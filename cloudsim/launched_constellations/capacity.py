"""Room for launches: what a provider can still take, net of launches not created yet.

A launch that does not fit is refused before anything is recorded, with the figure, rather
than failing halfway when the machine runs out.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

from sqlalchemy import select, text
from sqlalchemy.orm import selectinload

from cloudsim.auth.policy import Actor, require_role
from cloudsim.config import Config
from cloudsim.errors import Conflict, InvalidInput
from cloudsim.extensions import db
from cloudsim.models import Constellation, ConstellationState, Role
from cloudsim.providers.service import CONSTELLATION_TAG, PROVIDERS, Provider, open_provider
from constellations.definition import ConstellationKind, available_kinds, load_kind, parse_kind
from constellations.plans import PLANS
from provisioners.providers.capacity import Capacity, Demand

MACHINE_TAG = "cloudsim:machine"
NOT_CREATED_YET = (ConstellationState.PENDING, ConstellationState.LAUNCHING)
# one launch at a time checks and claims room (PostgreSQL; SQLite writes one at a time anyway)
ROOM_LOCK = 0x436C6F756453696D  # "CloudSim"


class CapacityExceeded(Conflict):
    """The provider cannot take the launch; the message says how much room there is."""


@dataclass(frozen=True)
class Room:
    """A provider's capacity and how many more of each kind fit in it."""

    provider: str
    capacity: Capacity
    kinds: dict[str, int]


def demand_of(kind: ConstellationKind) -> Demand:
    """Return what launching kind takes: its machines, one network, its public addresses."""
    return Demand(
        hosts=len(kind.machines),
        networks=1,
        public=sum(m.public for m in kind.machines),
        roles=tuple(m.role for m in kind.machines),
    )


def fits(capacity: Capacity, demand: Demand) -> int:
    """Return how many launches of demand fit in capacity."""
    counts = [
        room // wanted
        for room, wanted in (
            (capacity.hosts, demand.hosts),
            (capacity.networks, demand.networks),
            (capacity.public, demand.public),
            (capacity.memory_mib or 0, capacity.memory_of(demand)),
        )
        if wanted
    ]
    return min(counts, default=0)


def pending_demand(provider: Provider) -> Demand:
    """Return what recorded launches of this provider will still create."""
    launching = db.session.scalars(
        select(Constellation)
        .where(Constellation.provider == provider.name, Constellation.state.in_(NOT_CREATED_YET))
        .options(selectinload(Constellation.machines))
    ).all()
    if not launching:
        return Demand()
    made = {
        (node.extra["tags"].get(CONSTELLATION_TAG), node.extra["tags"].get(MACHINE_TAG))
        for node in provider.nodes()
    }
    networks = {network.name for network in provider.driver.ex_list_networks()}
    hosts = public = 0
    roles: list[str] = []
    for constellation in launching:
        kind = (
            parse_kind(constellation.definition, set(PLANS))
            if constellation.definition is not None
            else load_kind(constellation.kind, set(PLANS))
        )
        for machine in kind.machines:
            if (constellation.name, machine.name) not in made:
                hosts += 1
                public += machine.public
                roles.append(machine.role)
    unmade_networks = sum(c.name not in networks for c in launching)
    return Demand(hosts=hosts, networks=unmade_networks, public=public, roles=tuple(roles))


def room(provider_name: str, config: Config) -> Room | None:
    """Return the provider's room for launches, None when the provider does not know it."""
    provider = open_provider(provider_name, config)
    capacity = provider.driver.ex_capacity()
    if capacity is None:
        return None
    pending = pending_demand(provider)
    if pending != Demand():
        capacity = provider.driver.ex_capacity(pending)
        assert capacity is not None  # known a moment ago
    kinds = {name: fits(capacity, demand) for name, demand in kind_demands().items()}
    return Room(provider_name, capacity, kinds)


@functools.cache
def kind_demands() -> dict[str, Demand]:
    """Return what launching each shipped kind takes (package data: read once per process)."""
    return {name: demand_of(load_kind(name, set(PLANS))) for name in available_kinds()}


def visible_room(actor: Actor, provider_name: str, config: Config) -> Room | None:
    """Return the provider's room for launches (officers and admins)."""
    require_role(actor, Role.OFFICER, "see the providers' capacity")
    if provider_name not in PROVIDERS:
        raise InvalidInput(f"unknown provider {provider_name!r}; known: {', '.join(PROVIDERS)}")
    return room(provider_name, config)


def describe(found: Room | None) -> str:
    """Return one line saying how much more the provider can take."""
    if found is None:
        return "the provider does not say how much more it can take"
    capacity = found.capacity
    kinds = ", ".join(f"{count} {kind}" for kind, count in found.kinds.items())
    memory = (
        f", {capacity.memory_mib} MiB of memory ({capacity.memory_limited_by})"
        if capacity.memory_mib is not None
        else ""
    )
    return (
        f"{found.provider}: room for {capacity.hosts} more host(s) ({kinds}; "
        f"limited by {capacity.limited_by}){memory}"
    )


def require_room(provider_name: str, kind: ConstellationKind, config: Config) -> None:
    """Refuse (CapacityExceeded) a launch of kind the provider has no room for."""
    if db.engine.dialect.name == "postgresql":
        db.session.execute(text("SELECT pg_advisory_xact_lock(:key)"), {"key": ROOM_LOCK})
    found = room(provider_name, config)
    if found is None:
        return
    short = found.capacity.shortfall(demand_of(kind))
    if short is not None:
        raise CapacityExceeded(f"cannot launch a {kind.name} constellation: {short}")
