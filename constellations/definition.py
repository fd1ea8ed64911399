"""A constellation kind, loaded from YAML and validated; errors name the offending field."""

from __future__ import annotations

import ipaddress
import re
from dataclasses import dataclass
from importlib import resources
from importlib.resources.abc import Traversable
from typing import Any

import yaml

from provisioners.remote.firewall import (
    SOURCE_ANY,
    SOURCE_LAN,
    SOURCE_PUBLIC,
    FirewallRule,
    check_role_name,
)

KINDS_DIR: Traversable = resources.files("constellations").joinpath("kinds")
PUBLIC = "public"  # the outside world, in reachability checks
VPN = "vpn"  # a client of the router's team VPN, in reachability checks
_NAME = re.compile(r"[a-z][a-z0-9-]{0,30}\Z")


class DefinitionError(ValueError):
    """A constellation definition is malformed; the message names the field."""


@dataclass(frozen=True)
class MachineDefinition:
    """One machine of a kind: its role, size, address in the subnet and deploy plan."""

    name: str
    role: str
    size: str
    host: int
    public: bool
    plan: tuple[str, ...]

    def address(self, subnet: str) -> str:
        """Return this machine's private address in the given subnet."""
        network = ipaddress.ip_network(subnet)
        if self.host >= network.num_addresses - 1:
            raise DefinitionError(f"machine {self.name}: host {self.host} is outside {subnet}")
        return str(network.network_address + self.host)


@dataclass(frozen=True)
class Reachability:
    """A connection the verification stage expects to succeed (allow) or fail (deny)."""

    source: str
    target: str
    port: int
    allowed: bool


@dataclass(frozen=True)
class ConstellationKind:
    """Everything the engine needs to launch and verify one kind of constellation."""

    name: str
    description: str
    subnet_prefix: int
    gateway: str | None
    machines: tuple[MachineDefinition, ...]
    firewall: tuple[FirewallRule, ...]
    reachability: tuple[Reachability, ...]
    vpn_access: tuple[FirewallRule, ...] = ()  # what VPN clients reach (source: the VPN)

    def machine(self, name: str) -> MachineDefinition:
        """Return the machine called name."""
        for machine in self.machines:
            if machine.name == name:
                return machine
        raise KeyError(name)

    @property
    def roles(self) -> list[str]:
        """Return the roles, in machine order, without repeats."""
        return list(dict.fromkeys(m.role for m in self.machines))


def _field(data: dict[str, Any], key: str, where: str, kind: type, default: Any = ...) -> Any:
    if key not in data:
        if default is ...:
            raise DefinitionError(f"{where}.{key} is required")
        return default
    value = data[key]
    if (kind is int and isinstance(value, bool)) or not isinstance(value, kind):
        raise DefinitionError(f"{where}.{key} must be a {kind.__name__}, got {value!r}")
    return value


def _name(value: str, where: str) -> str:
    if not _NAME.match(value):
        raise DefinitionError(f"{where} must be lowercase letters, digits and '-', got {value!r}")
    return value


def _machine(data: Any, where: str, plans: set[str] | None) -> MachineDefinition:
    if not isinstance(data, dict):
        raise DefinitionError(f"{where} must be a mapping")
    name = _name(_field(data, "name", where, str), f"{where}.name")
    role = _field(data, "role", where, str, name)
    try:
        check_role_name(f"{where}.role", role)
    except ValueError as exc:
        raise DefinitionError(str(exc)) from None
    host = _field(data, "host", where, int)
    if not 2 <= host <= 254:
        raise DefinitionError(f"{where}.host must be between 2 and 254, got {host}")
    plan = _field(data, "plan", where, list)
    for step in plan:
        if not isinstance(step, str) or (plans is not None and step not in plans):
            known = ", ".join(sorted(plans or ()))
            raise DefinitionError(f"{where}.plan: unknown deploy plan {step!r} (known: {known})")
    return MachineDefinition(
        name=name,
        role=role,
        size=_field(data, "size", where, str, "small"),
        host=host,
        public=_field(data, "public", where, bool, False),
        plan=tuple(plan),
    )


def _rule(data: Any, where: str, roles: set[str], vpn: bool = False) -> FirewallRule:
    if not isinstance(data, dict):
        raise DefinitionError(f"{where} must be a mapping")
    ports = data.get("ports")
    if isinstance(ports, int) and not isinstance(ports, bool):
        ports = (ports, ports)
    elif isinstance(ports, list) and len(ports) == 2:
        ports = (ports[0], ports[1])
    elif ports is not None:
        raise DefinitionError(f"{where}.ports must be a port or [first, last], got {ports!r}")
    if vpn and "from" in data:
        raise DefinitionError(f"{where}.from: the source of a vpn rule is the VPN")
    source = SOURCE_ANY if vpn else _field(data, "from", where, str)
    if source not in (SOURCE_ANY, SOURCE_LAN, SOURCE_PUBLIC):
        source = f"role:{source}"
    try:
        rule = FirewallRule(
            to_role=_field(data, "to", where, str),
            protocol=_field(data, "protocol", where, str, "tcp"),
            ports=ports,
            source=source,
        )
    except ValueError as exc:
        raise DefinitionError(f"{where}: {exc}") from None
    for role in (rule.to_role, rule.source_role):
        if role is not None and role not in roles:
            raise DefinitionError(f"{where}: no machine has role {role!r}")
    return rule


def _reachability(data: Any, where: str, names: set[str], allowed: bool) -> Reachability:
    if not (isinstance(data, list) and len(data) == 3 and isinstance(data[2], int)):
        raise DefinitionError(f"{where} must be [source, target, port]")
    source, target, port = data
    for end in (source, target):
        if end not in names | {PUBLIC, VPN}:
            raise DefinitionError(f"{where}: unknown machine {end!r}")
    if target in (PUBLIC, VPN):
        raise DefinitionError(f"{where}: the target must be a machine, got {target!r}")
    return Reachability(source, target, port, allowed)


def parse_kind(data: Any, plans: set[str] | None = None) -> ConstellationKind:
    """Validate a kind given as parsed YAML; `plans` lists the deploy plans that exist."""
    if not isinstance(data, dict):
        raise DefinitionError("a constellation kind must be a mapping")
    name = _name(_field(data, "name", "kind", str), "name")
    network = _field(data, "network", name, dict, {})
    prefix = _field(network, "prefix", f"{name}.network", int, 24)
    if not 16 <= prefix <= 28:
        raise DefinitionError(f"{name}.network.prefix must be between 16 and 28, got {prefix}")
    raw_machines = _field(data, "machines", name, list)
    if not raw_machines:
        raise DefinitionError(f"{name}.machines must list at least one machine")
    machines = tuple(
        _machine(m, f"{name}.machines[{i}]", plans) for i, m in enumerate(raw_machines)
    )
    names = [m.name for m in machines]
    if len(set(names)) != len(names):
        raise DefinitionError(f"{name}.machines: machine names must be unique")
    if len({m.host for m in machines}) != len(machines):
        raise DefinitionError(f"{name}.machines: two machines have the same host number")
    gateway = network.get("gateway")
    if gateway is not None and gateway not in names:
        raise DefinitionError(f"{name}.network.gateway: no machine named {gateway!r}")
    roles = {m.role for m in machines}
    firewall = tuple(
        _rule(r, f"{name}.firewall[{i}]", roles)
        for i, r in enumerate(_field(data, "firewall", name, list, []))
    )
    vpn_access = tuple(
        _rule(r, f"{name}.vpn[{i}]", roles, vpn=True)
        for i, r in enumerate(_field(data, "vpn", name, list, []))
    )
    checks = _field(data, "reachability", name, dict, {})
    reachability = tuple(
        _reachability(r, f"{name}.reachability.{key}[{i}]", set(names), key == "allow")
        for key in ("allow", "deny")
        for i, r in enumerate(_field(checks, key, f"{name}.reachability", list, []))
    )
    return ConstellationKind(
        name=name,
        description=_field(data, "description", name, str, ""),
        subnet_prefix=prefix,
        gateway=gateway,
        machines=machines,
        firewall=firewall,
        reachability=reachability,
        vpn_access=vpn_access,
    )


def kind_data(name: str, directory: Traversable = KINDS_DIR) -> Any:
    """Read the YAML data of the kind called name (not yet validated: see parse_kind)."""
    path = directory.joinpath(f"{name}.yaml")
    if not _NAME.match(name) or not path.is_file():
        known = ", ".join(available_kinds(directory))
        raise DefinitionError(f"unknown constellation kind {name!r} (known: {known})")
    try:
        return yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise DefinitionError(f"{path.name}: {exc}") from None


def load_kind(
    name: str, plans: set[str] | None = None, directory: Traversable = KINDS_DIR
) -> ConstellationKind:
    """Load and validate the kind called name from its YAML file."""
    path = directory.joinpath(f"{name}.yaml")
    kind = parse_kind(kind_data(name, directory), plans)
    if kind.name != name:
        raise DefinitionError(f"{path.name}: name must be {name!r}, got {kind.name!r}")
    return kind


def available_kinds(directory: Traversable = KINDS_DIR) -> list[str]:
    """Return the names of the kinds defined in the directory (package data by default)."""
    return sorted(
        p.name.removesuffix(".yaml") for p in directory.iterdir() if p.name.endswith(".yaml")
    )
