"""What the router gets: forwarding between the VPN and the LAN, never public to LAN."""

from __future__ import annotations

from constellations.plans.base import PlanContext, PlanItem
from provisioners.operations import iptables_chain, iptables_rule, sysctl

FORWARD_CHAIN = "CLOUDSIM-FWD"


def router(ctx: PlanContext) -> list[PlanItem]:
    """Forward VPN and LAN traffic; never let the public side into the LAN."""
    return [
        sysctl({"net.ipv4.ip_forward": 1}, templates=ctx.templates),
        iptables_chain(FORWARD_CHAIN),
        iptables_rule(
            FORWARD_CHAIN, ["-m", "conntrack", "--ctstate", "ESTABLISHED,RELATED", "-j", "ACCEPT"]
        ),
        iptables_rule(FORWARD_CHAIN, ["-i", "tun+", "-d", ctx.subnet, "-j", "ACCEPT"]),
        iptables_rule(FORWARD_CHAIN, ["-s", ctx.subnet, "-j", "ACCEPT"]),
        iptables_rule(FORWARD_CHAIN, ["-d", ctx.subnet, "-j", "DROP"]),
        iptables_rule("FORWARD", ["-j", FORWARD_CHAIN], insert=True),
    ]
