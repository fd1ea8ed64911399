"""What every machine gets: its peers' names, its route out, and (a stage of its own) a firewall."""

from __future__ import annotations

from constellations.plans.base import PlanContext, PlanItem
from provisioners.remote.firewall import SOURCE_ANY, SOURCE_LAN, SOURCE_PUBLIC, FirewallRule
from provisioners.remote.operations import (
    deb_packages,
    default_route,
    file,
    iptables_chain_exact,
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
    """Plan the host firewall: the kind's rules for this role, then drop everything else.

    The chain holds exactly these rules: a rule an older plan allowed is taken out.
    """
    return [
        iptables_chain_exact(FIREWALL_CHAIN, host_firewall_rules(ctx)),
        iptables_rule("INPUT", ["-j", FIREWALL_CHAIN], insert=True),
    ]


def host_firewall_rules(ctx: PlanContext) -> list[list[str]]:
    """Return the rules of this machine's firewall chain, in order (the last drops)."""
    return [
        ["-i", "lo", "-j", "ACCEPT"],
        ["-m", "conntrack", "--ctstate", "ESTABLISHED,RELATED", "-j", "ACCEPT"],
        *(
            [*source, *match(rule), "-j", "ACCEPT"]
            for rule in ctx.kind.firewall
            if rule.to_role == ctx.machine.role
            for source in _sources(rule, ctx)
        ),
        ["-j", "DROP"],
    ]


def _sources(rule: FirewallRule, ctx: PlanContext) -> list[list[str]]:
    if rule.source == SOURCE_ANY:
        return [[]]
    if rule.source == SOURCE_LAN:
        return [["-s", ctx.subnet]]
    if rule.source == SOURCE_PUBLIC:
        return [["!", "-s", ctx.subnet]]
    return [["-s", f"{address}/32"] for address in ctx.addresses_of_role(rule.source_role or "")]


def match(rule: FirewallRule) -> list[str]:
    """Return the iptables match (protocol, ports) of a rule."""
    if rule.protocol == "all":
        return []
    match = ["-p", rule.protocol]
    if rule.ports is not None:
        first, last = rule.ports
        match += ["--dport", str(first) if first == last else f"{first}:{last}"]
    return match
