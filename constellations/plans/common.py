"""What every machine gets: its peers' names, its route out, and (a stage of its own) a firewall."""

from __future__ import annotations

from constellations.plans.base import PlanContext, PlanItem
from provisioners.remote.firewall import SOURCE_ANY, SOURCE_LAN, FirewallRule
from provisioners.remote.operations import (
    deb_packages,
    default_route,
    file,
    iptables_chain,
    iptables_rule,
)

FIREWALL_CHAIN = "CLOUDSIM-IN"
MACHINE_PACKAGES = ("python3-venv", "python3-pip")


def common(ctx: PlanContext) -> list[PlanItem]:
    """Plan the files and firewall every machine of a constellation has."""
    hosts = ctx.templates.render(
        "common/hosts.j2", {"hostname": ctx.hostname, "addresses": ctx.addresses}
    )
    motd = ctx.templates.render(
        "common/motd.j2",
        {
            "constellation": ctx.constellation,
            "machine": ctx.machine.name,
            "role": ctx.machine.role,
            "team": ctx.team,
        },
    )
    items: list[PlanItem] = [
        # Machines have no internet: their image must carry these (the offline installs use
        # them); this says so clearly where one does not.
        deb_packages(MACHINE_PACKAGES),
        file("/etc/hosts", hosts),
        file("/etc/motd", motd),
    ]
    gateway = ctx.kind.gateway
    if gateway is not None and gateway != ctx.machine.name and not ctx.machine.public:
        items.append(default_route(ctx.addresses[gateway]))
    return items


def firewall(ctx: PlanContext) -> list[PlanItem]:
    """Plan the host firewall: the kind's rules for this role, then drop everything else."""
    rules = [rule for rule in ctx.kind.firewall if rule.to_role == ctx.machine.role]
    operations: list[PlanItem] = [
        iptables_chain(FIREWALL_CHAIN),
        iptables_rule(FIREWALL_CHAIN, ["-i", "lo", "-j", "ACCEPT"]),
        iptables_rule(
            FIREWALL_CHAIN, ["-m", "conntrack", "--ctstate", "ESTABLISHED,RELATED", "-j", "ACCEPT"]
        ),
    ]
    for rule in rules:
        for source in _sources(rule, ctx):
            operations.append(
                iptables_rule(FIREWALL_CHAIN, [*source, *_match(rule), "-j", "ACCEPT"])
            )
    operations.append(iptables_rule(FIREWALL_CHAIN, ["-j", "DROP"]))
    operations.append(iptables_rule("INPUT", ["-j", FIREWALL_CHAIN], insert=True))
    return operations


def _sources(rule: FirewallRule, ctx: PlanContext) -> list[list[str]]:
    if rule.source == SOURCE_ANY:
        return [[]]
    if rule.source == SOURCE_LAN:
        return [["-s", ctx.subnet]]
    return [["-s", f"{address}/32"] for address in ctx.addresses_of_role(rule.source_role or "")]


def _match(rule: FirewallRule) -> list[str]:
    if rule.protocol == "all":
        return []
    match = ["-p", rule.protocol]
    if rule.ports is not None:
        first, last = rule.ports
        match += ["--dport", str(first) if first == last else f"{first}:{last}"]
    return match
