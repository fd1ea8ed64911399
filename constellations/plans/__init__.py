"""Deploy plans: what each machine role gets, as idempotent operations and actions.

A kind's YAML names plans per machine (`plan: [common, router]`); the engine looks them up
here. Adding a plan means adding a function to PLANS, not changing the engine.
"""

from __future__ import annotations

from collections.abc import Callable

from constellations.plans.base import Action, PlanContext, PlanItem
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

__all__ = ["PLANS", "Action", "Plan", "PlanContext", "PlanItem", "firewall"]
