"""Reach machines over SSH: targets for the executor, host keys kept in the database."""

from __future__ import annotations

from collections.abc import Iterable

from libcloud.compute.base import Node
from sqlalchemy import update
from sqlalchemy.engine import Engine

from cloudsim.extensions import db
from cloudsim.launched_constellations.keys import KeyPair
from cloudsim.models import Constellation, Machine
from provisioners.ssh import Machine as Target


class MachineHostKeys:
    """Trust-on-first-use host keys kept on the machines' rows (usable from worker threads)."""

    def __init__(self, constellation: Constellation) -> None:
        self._engine: Engine = db.engine
        self._ids = {target_name(constellation, m.name): m.id for m in constellation.machines}
        self._keys = {
            target_name(constellation, m.name): m.host_key for m in constellation.machines
        }

    def get(self, machine_name: str) -> str | None:
        return self._keys.get(machine_name)

    def put(self, machine_name: str, key_type_and_base64: str) -> None:
        self._keys[machine_name] = key_type_and_base64
        with self._engine.begin() as conn:
            conn.execute(
                update(Machine)
                .where(Machine.id == self._ids[machine_name])
                .values(host_key=key_type_and_base64)
            )


def target_name(constellation: Constellation, machine_name: str) -> str:
    """Return the name a machine goes by in logs and the host key store."""
    return f"{constellation.name}/{machine_name}"


def targets(
    constellation: Constellation, nodes: Iterable[Node], keys: KeyPair
) -> dict[str, Target]:
    """Return an SSH target per machine name.

    A provider that can carry the connection itself (the local one: into a namespace) says so
    with `ssh_proxy_command`; otherwise public machines are reached directly and private ones
    through the first public machine, as a jump host.
    """
    by_name = {
        node.extra.get("tags", {}).get("cloudsim:machine", node.name): node for node in nodes
    }
    public = next((m for m in constellation.machines if m.public_ip), None)
    result: dict[str, Target] = {}
    jump: Target | None = None
    if public is not None:
        jump = _target(constellation, public, by_name.get(public.name), keys, None)
    for machine in constellation.machines:
        result[machine.name] = _target(
            constellation, machine, by_name.get(machine.name), keys, jump
        )
    return result


def _target(
    constellation: Constellation,
    machine: Machine,
    node: Node | None,
    keys: KeyPair,
    jump: Target | None,
) -> Target:
    name = target_name(constellation, machine.name)
    extra = node.extra if node is not None else {}
    login = {"user": extra.get("ssh_user", "root"), "port": int(extra.get("ssh_port", 22))}
    if extra.get("ssh_proxy_command"):
        return Target(
            name=name,
            host=machine.private_ip or "",
            private_key=keys.private,
            proxy_command=list(extra["ssh_proxy_command"]),
            **login,
        )
    # Existing servers say where the controller reaches them; cloud machines do not.
    address = extra.get("ssh_address") or machine.public_ip
    if address:
        return Target(name=name, host=address, private_key=keys.private, **login)
    return Target(
        name=name, host=machine.private_ip or "", private_key=keys.private, jump=jump, **login
    )
