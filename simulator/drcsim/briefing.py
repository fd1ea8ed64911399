"""The course briefing a team gets: the task, and where things roughly are (as the VRC gave).

Exact poses would make perception pointless, so every position is given with a seeded error
of the size stated beside it (`accuracy_m`, a bound); the robot's own start pose is exact.
"""

from __future__ import annotations

import copy
import math
from typing import Any

import numpy as np

from drcsim.worlds import WorldSpec

# Bound of the position error (m) and yaw error (rad) per kind of object.
ACCURACY = {"gates": (0.25, 0.05), "vehicle": (0.25, 0.04), "table": (0.1, 0.03)}
SMALL = (0.08, 0.03)  # hose coupler, standpipe (inlet and valve move with it)


def _error(rng: np.random.Generator, bound: float) -> tuple[float, float]:
    radius, angle = bound * math.sqrt(rng.uniform()), rng.uniform(-math.pi, math.pi)
    return radius * math.cos(angle), radius * math.sin(angle)


def _shift(point: list[float], dx: float, dy: float) -> list[float]:
    return [round(point[0] + dx, 2), round(point[1] + dy, 2), *point[2:]]


def rough_briefing(course: dict[str, Any], spec: WorldSpec) -> dict[str, Any]:
    """Return the briefing for `course` (exact poses from the scene) with seeded errors."""
    rng = np.random.default_rng([spec.seed, 4242])
    rough = copy.deepcopy(course)
    for name, gate in sorted(rough.get("gates", {}).items()):
        dx, dy = _error(rng, ACCURACY["gates"][0])
        gate["pose"] = _shift(gate["pose"], dx, dy)
        gate["pose"][2] = round(gate["pose"][2] + rng.uniform(-1, 1) * ACCURACY["gates"][1], 3)
        gate["accuracy_m"] = ACCURACY["gates"][0]
        rough["gates"][name] = gate
    for name in ("vehicle", "table"):
        if name in rough:
            bound, yaw_bound = ACCURACY[name]
            dx, dy = _error(rng, bound)
            item = rough[name]
            item["pose"] = _shift(item["pose"], dx, dy)
            item["pose"][2] = round(item["pose"][2] + rng.uniform(-1, 1) * yaw_bound, 3)
            if "driver_door" in item:
                item["driver_door"] = _shift(item["driver_door"], dx, dy)
            item["accuracy_m"] = bound
    if "hose" in rough:
        dx, dy = _error(rng, SMALL[0])
        rough["hose"]["coupler"] = _shift(rough["hose"]["coupler"], dx, dy)
        rough["hose"]["accuracy_m"] = SMALL[0]
    if "standpipe" in rough:
        dx, dy = _error(rng, SMALL[0])
        pipe = rough["standpipe"]
        for key in ("pose", "inlet", "valve"):
            pipe[key] = _shift(pipe[key], dx, dy)
        pipe["accuracy_m"] = SMALL[0]
    # The VRC's task descriptions laid out the course's sections: where each patch of
    # terrain lies (its area, to the decimetre) and what it is, not what it holds.
    rough["terrain"] = {
        name: {
            "kind": patch["kind"],
            "min": [round(v, 1) for v in patch["min"]],
            "max": [round(v, 1) for v in patch["max"]],
        }
        for name, patch in sorted(spec.terrain.items())
    }
    rough["task"] = {
        "title": spec.title,
        "checkpoints": [c["name"] for c in spec.checkpoints],
        "note": "positions are rough (error up to accuracy_m); find the objects with the sensors",
    }
    return rough
