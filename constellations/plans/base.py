"""What a plan is given (PlanContext) and what it returns (operations and actions)."""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path

from constellations.definition import ConstellationKind, MachineDefinition
from provisioners.remote.operations import MachineTemplates, Operation, apply
from provisioners.remote.ssh import SSHExecutor, SSHTarget


@dataclass(frozen=True)
class Action:
    """A step too big for an operation's in-memory upload (e.g. a wheelhouse); idempotent.

    `run` returns True when it changed the machine.
    """

    name: str
    run: Callable[[SSHExecutor, SSHTarget], bool]


PlanItem = Operation | Action


def apply_plan(executor: SSHExecutor, target: SSHTarget, items: list[PlanItem]) -> int:
    """Apply plan items to a machine in order; return how many changed it."""
    changed = 0
    for item in items:
        if isinstance(item, Action):
            executor.log(target.name, f"[{item.name}]")  # operations log their own verdict
            changed += item.run(executor, target)
        else:
            changed += apply(executor, target, item).changed
    return changed


class Need(StrEnum):
    """Something a plan needs in its PlanContext that the launch job makes for it."""

    # supplied in this order
    SIMULATOR_WHEELS = "simulator_wheels"  # wheelhouse: drcsim and its dependencies
    CLOUDSIM_BUNDLE = "cloudsim_bundle"  # app_bundle and the admin password in secrets
    VPN = "vpn"  # vpn: the constellation's PKI for the router's VPN server
    ROUTER_WHEELS = "router_wheels"  # router_wheelhouse: csrouter and its dependencies


@dataclass(frozen=True)
class VpnMaterial:
    """What the router's VPN server needs: the constellation's PKI (PEM) and tunnel settings."""

    ca_cert: str
    server_cert: str
    server_key: str = field(repr=False)
    crl: str = ""
    revoked: tuple[str, ...] = ()  # certificate names whose sessions the router must end
    network: str = "10.8.0.0/24"  # addresses handed to VPN clients
    port: int = 1194


# A member's uid on the field computers is this plus their CloudSim user id: the same on fc1
# and fc2, stable across renames, and clear of system (< 1000), ordinary (< 60000), systemd's
# dynamic (61184-65519) and subordinate (100000 + 65536 per user) ranges.
MEMBER_UID_BASE = 300000
MEMBER_UID_SPAN = 100000  # user ids below this only


@dataclass(frozen=True)
class MemberAccount:
    """A team member's own Unix account on the field computers: who, and the keys that log in."""

    user_id: int
    email: str
    keys: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not 0 < self.user_id < MEMBER_UID_SPAN:
            raise ValueError(f"no field-computer account for user id {self.user_id}")

    @property
    def name(self) -> str:
        """Return the account's name: the e-mail's local part, made safe, then the user id."""
        return member_account_name(self.email, self.user_id)

    @property
    def uid(self) -> int:
        """Return the account's uid (the same on every field computer)."""
        return MEMBER_UID_BASE + self.user_id


def member_account_name(email: str, user_id: int) -> str:
    """Return a member's account name, e.g. alice.smith@x.org, id 7 -> alice_smith-7.

    The id makes it unique and keeps system accounts (never named <word>-<digits>) apart; the
    local part only helps people read logs. Only [a-z0-9_-], 28 characters at most.
    """
    local = re.sub(r"[^a-z0-9]+", "_", email.split("@", 1)[0].lower()).strip("_")[:20]
    if not local or not local[0].isalpha():
        local = f"m{local}"[:20]
    return f"{local}-{int(user_id)}"


@dataclass(frozen=True)
class PlanContext:
    """Everything a plan may use about the machine it deploys and its constellation."""

    constellation: str
    team: str
    kind: ConstellationKind
    machine: MachineDefinition
    subnet: str
    addresses: dict[str, str]
    wheelhouse: Path | None = None
    vpn: VpnMaterial | None = None  # routers only
    router_wheelhouse: Path | None = None  # routers with a VPN: csrouter and its wheels
    app_bundle: Path | None = None  # CloudSim servers only: source + wheels
    # CloudSim servers only: the real-time factor the competition needs, handed down by the
    # master so that its instances verify simulators against the same figure
    sim_min_rtf: float = 1.0
    secrets: Mapping[str, str] = field(default_factory=dict, repr=False)
    members: tuple[MemberAccount, ...] = ()  # field computers: the team's active members
    team_sudo: bool = False  # field computers: may the members use sudo
    templates: MachineTemplates = field(default_factory=MachineTemplates)

    @property
    def hostname(self) -> str:
        """Return the machine's host name (the provider's node name)."""
        return f"{self.constellation}-{self.machine.name}"

    def addresses_of_role(self, role: str) -> list[str]:
        """Return the private addresses of every machine with this role."""
        return [self.addresses[m.name] for m in self.kind.machines if m.role == role]
