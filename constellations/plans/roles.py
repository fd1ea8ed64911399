"""What each role gets beyond the common plan."""

from __future__ import annotations

from constellations.plans.base import PlanContext, PlanItem
from constellations.plans.software import install_wheelhouse
from provisioners.operations import iptables_chain, iptables_rule, sysctl

FORWARD_CHAIN = "CLOUDSIM-FWD"
SIMULATOR_VENV = "/opt/drcsim"


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


def simulator(ctx: PlanContext) -> list[PlanItem]:
    """Install the bundled simulator (drcsim) into its own virtualenv."""
    return [install_wheelhouse(_wheelhouse(ctx), SIMULATOR_VENV, "drcsim")]


def field_computer(ctx: PlanContext) -> list[PlanItem]:
    """Install drcsim for its client library, which team code uses to drive the robot."""
    return [install_wheelhouse(_wheelhouse(ctx), SIMULATOR_VENV, "drcsim")]


def cloudsim_server(ctx: PlanContext) -> list[PlanItem]:
    """Install CloudSim itself (not yet: see the README's status of the cloudsim kind)."""
    raise NotImplementedError("the cloudsim kind's server plan is not built yet")


def _wheelhouse(ctx: PlanContext):  # type: ignore[no-untyped-def]
    if ctx.wheelhouse is None:
        raise ValueError(f"{ctx.machine.name}: this plan needs the simulator's wheelhouse")
    return ctx.wheelhouse
