"""Reach machines over SSH: routes recorded on the machines' rows, host keys kept there too."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import replace

from libcloud.compute.base import Node
from sqlalchemy import select, update

from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.launched_constellations.keys import KeyPair
from cloudsim.models import Constellation, Machine
from cloudsim.models.machines import GONE
from cloudsim.providers.service import Provider, open_provider
from provisioners.providers.base import BEHIND_PUBLIC_MACHINE
from provisioners.remote.ssh import ConnectionCache, HostKeys, Route, SSHTarget, process_cache


def machine_host_keys(constellation: Constellation) -> HostKeys:
    """Return trust-on-first-use host keys kept on the machines' rows (usable from threads)."""
    engine = db.engine  # worker threads write on their own connections
    ids = {target_name(constellation, m.name): m.id for m in constellation.machines}
    keys = {target_name(constellation, m.name): m.host_key for m in constellation.machines}

    def record(machine_name: str, key_type_and_base64: str) -> None:
        with engine.begin() as conn:
            conn.execute(
                update(Machine)
                .where(Machine.id == ids[machine_name])
                .values(host_key=key_type_and_base64)
            )

    return HostKeys(lookup=keys.get, record=record)


def target_name(constellation: Constellation, machine_name: str) -> str:
    """Return the name a machine goes by in logs and the host key store."""
    return f"{constellation.name}/{machine_name}"


def record_routes(constellation: Constellation, provider: Provider, nodes: Iterable[Node]) -> None:
    """Store on each machine's row how the controller reaches it, as the provider says.

    Asked once, when the machines are created: runs and the beat then reach them from the
    rows alone, without listing the provider's nodes.
    """
    rows = {m.name: m for m in constellation.machines}
    public = next((m.name for m in constellation.machines if m.public_ip), None)
    for node in nodes:
        row = rows.get(node.extra.get("tags", {}).get("cloudsim:machine", node.name))
        if row is None:
            continue
        route = provider.driver.ex_ssh_route(node)
        if route.jump == BEHIND_PUBLIC_MACHINE:
            route = replace(route, jump=public if public != row.name else None)
        row.ssh_route = route.to_json()


def targets(constellation: Constellation, keys: KeyPair, config: Config) -> dict[str, SSHTarget]:
    """Return an SSH target per machine name, from the routes on the machines' rows."""
    if any(m.ssh_route is None for m in constellation.machines):
        # rows from before routes were recorded: ask the provider once
        provider = open_provider(constellation.provider, config)
        record_routes(constellation, provider, provider.nodes(constellation.name))
        db.session.flush()  # the caller's boundary commits them
    routes = {
        m.name: Route.from_json(m.ssh_route) if m.ssh_route else Route(host=m.private_ip or "")
        for m in constellation.machines
    }
    result: dict[str, SSHTarget] = {}

    def target(name: str) -> SSHTarget:
        if name not in result:
            route = routes[name]
            jump = target(route.jump) if route.jump else None
            result[name] = route.target(target_name(constellation, name), keys.private, jump)
        return result[name]

    for name in routes:
        target(name)
    return result


def forget_connections(constellation: Constellation, cache: ConnectionCache | None = None) -> int:
    """Close this process's kept SSH connections to the constellation's machines."""
    prefix = target_name(constellation, "")
    return (cache or process_cache()).evict_where(lambda name: name.startswith(prefix))


def forget_gone_connections(cache: ConnectionCache) -> int:
    """Close kept connections to machines of constellations terminated (by any process)."""
    gone = GONE
    live = set(
        db.session.scalars(select(Constellation.name).where(Constellation.state.not_in(gone)))
    )
    return cache.evict_where(lambda name: name.rsplit("/", 1)[0] not in live)
