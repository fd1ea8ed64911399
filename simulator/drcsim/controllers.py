"""The three reference team controllers, all over the network API: naive, example, careful.

They differ only in care: the naive one walks straight at each goal, drives flat out with a
lazy steering hand and tries each grasp once; the careful one drives gently, aims well past
each gate and feels around a denser grid before giving up.
"""

from __future__ import annotations

from drcsim.example_controller import SEARCH, ExampleController, grid


class NaiveController(ExampleController):
    """Straight at every goal, full throttle, one try at everything."""

    throttle = 1.0
    steer_gain = 2.5
    walk_past = 0.2
    search = [(0.0, 0.0)]
    grasp_search = [(0.0, 0.0)]
    straight = True
    approach_tries = 0
    # Faster than the walker's defaults (0.25 m, 0.6 s, 0.3 s): long, quick steps.
    gait = {"step_time": 0.4, "double_support": 0.1, "step_length": 0.4}


class CarefulController(ExampleController):
    """Gentle throttle, aims well past each gate, feels around a dense grid."""

    throttle = 0.45
    steer_gain = 8.0
    walk_past = 1.2
    approach_tries = 3
    avoid = ("rubble",)
    # Slower and shorter than the walker's defaults (0.25 m, 0.6 s, 0.3 s).
    gait = {"step_length": 0.2, "step_time": 0.8, "double_support": 0.5}
    search = SEARCH + [
        (dx, dy) for dx in (-0.09, -0.03, 0.03, 0.09) for dy in (-0.09, -0.03, 0.03, 0.09)
    ]
    grasp_search = grid(0.04, 0.12)


CONTROLLERS: dict[str, type[ExampleController]] = {
    "naive": NaiveController,
    "example": ExampleController,
    "careful": CarefulController,
}
