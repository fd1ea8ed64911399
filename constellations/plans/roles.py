"""What the simulator, field computer and CloudSim server roles get beyond the common plan."""

from __future__ import annotations

from constellations.plans.base import PlanContext, PlanItem
from constellations.plans.software import install_wheelhouse

SIMULATOR_VENV = "/opt/drcsim"


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
