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
    approach_door = False
    walk_tries = 1
    gait = {"step_time": 0.5, "double_support": 0.3, "step_length": 0.35}


class CarefulController(ExampleController):
    """Gentle throttle, aims well past each gate, feels around a dense grid."""

    throttle = 0.45
    steer_gain = 8.0
    walk_past = 1.2
    walk_tries = 3
    # The walker's own gait: a slower one (0.9 s on one foot, 0.2 m steps) fell sooner in
    # mud, where the stance foot tips further the longer it bears the robot alone.
    gait: dict[str, float] = {}
    search = SEARCH + [
        (dx, dy) for dx in (-0.09, -0.03, 0.03, 0.09) for dy in (-0.09, -0.03, 0.03, 0.09)
    ]
    grasp_search = grid(0.04, 0.12)


CONTROLLERS: dict[str, type[ExampleController]] = {
    "naive": NaiveController,
    "example": ExampleController,
    "careful": CarefulController,
}
