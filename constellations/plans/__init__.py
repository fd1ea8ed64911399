"""Deploy plans: what each machine role gets, as idempotent operations and actions.

A kind's YAML names plans per machine (`plan: [common, router]`); the launch job looks them
up here, and gives each the software it declares in NEEDS (wheelhouses, bundles, keys).
Adding a plan means adding a function to PLANS (and its needs), not changing the launch job.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

from constellations.plans.base import Action, Need, PlanContext, PlanItem, apply_plan
from constellations.plans.common import common, firewall
from constellations.plans.roles import cloudsim_server, field_computer, simulator
from constellations.plans.router import router

Plan = Callable[[PlanContext], list[PlanItem]]

PLANS: dict[str, Plan] = {
    "common": common,
    "router": router,
    "simulator": simulator,
    "field_computer": field_computer,
    "cloudsim_server": cloudsim_server,
}

# What each plan needs the launch job to put in its PlanContext; a plan not named needs nothing.
NEEDS: dict[str, frozenset[Need]] = {
    "router": frozenset({Need.VPN, Need.ROUTER_WHEELS}),
    "simulator": frozenset({Need.SIMULATOR_WHEELS}),
    "field_computer": frozenset({Need.SIMULATOR_WHEELS}),
    "cloudsim_server": frozenset({Need.CLOUDSIM_BUNDLE}),
}


def needs_of(plans: Iterable[str]) -> frozenset[Need]:
    """Return everything the named plans need, together."""
    return frozenset(need for plan in plans for need in NEEDS.get(plan, ()))


__all__ = [
    "NEEDS",
    "PLANS",
    "Action",
    "Need",
    "Plan",
    "PlanContext",
    "PlanItem",
    "apply_plan",
    "firewall",
    "needs_of",
]
