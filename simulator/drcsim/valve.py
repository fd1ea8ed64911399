"""The turn_valve behaviour: the hand takes the valve's rim and the arm turns it, in strokes."""

from __future__ import annotations

import math

from drcsim.assists import HAND_PARTS, Grasps
from drcsim.control import JointController
from drcsim.errors import CommandError
from drcsim.handles import Handle, Turner, set_friction
from drcsim.models import props
from drcsim.reach import ARM_JOINTS
from drcsim.scene import Scene

VALVE_REACH = 0.3  # palm to valve centre to start turning, metres
VALVE_FRICTION = 3.0  # N m of dry friction in the valve's stem
# Where on the rim each hand works (angle about the valve's axis from the standpipe's +y
# towards +z) and how far either side of it one stroke goes.
VALVE_HOME = {"left": 0.1, "right": math.pi + 0.1}
VALVE_STROKE = 0.8


class Valve:
    """The valve: a revolute joint with friction, turned only by a hand holding its rim."""

    def __init__(self, scene: Scene, controller: JointController, grasps: Grasps) -> None:
        self.scene, self.controller, self.grasps = scene, controller, grasps
        self.turner: Turner | None = None
        self.status_word = "idle"  # idle, turning, hand_off, stalled: why
        self.handle: Handle | None = None
        pipe = scene.standpipe
        if pipe is None:
            return
        self.handle = Handle("valve", pipe, 0, (1, 0, 0), (0, 1, 0), props.VALVE_RADIUS, True)
        grasps.handles.append(self.handle)
        set_friction(scene, self.handle, VALVE_FRICTION)
        # The fingers close around the rim: the hand never knocks the wheel about.
        for name in HAND_PARTS:
            for side in "lr":
                link = scene.robot_links[f"{side}_{name}"]
                scene.client.setCollisionFilterPair(scene.robot, pipe, link, 0, 0)

    def angle(self) -> float:
        """Return how far the valve has turned (rad): the joint's real angle."""
        return 0.0 if self.handle is None else self.handle.angle(self.scene)

    def centre(self) -> tuple[float, float, float]:
        """Return the valve wheel's centre in world coordinates."""
        assert self.scene.standpipe is not None
        return tuple(self.scene.client.getLinkState(self.scene.standpipe, 0)[4])  # type: ignore[return-value]

    def start(self, hand: str, angle: float) -> None:
        """Start turning by `angle` rad; raise if the hand is not at the valve."""
        if self.handle is None:
            raise CommandError("this world has no valve")
        if math.dist(self.grasps.palm(hand), self.centre()) > VALVE_REACH:
            raise CommandError(f"the {hand} hand is not at the valve (within {VALVE_REACH} m)")
        self.cancel()
        self.turner = Turner(
            self.scene,
            self.controller,
            self.grasps,
            self.handle,
            hand,
            VALVE_HOME[hand],
            VALVE_STROKE,
        )
        self.turner.goal = self.angle() + angle
        self.status_word = "turning"

    def owner(self, joint: str) -> str | None:
        """Return the behaviour owning `joint` (an arm turning the valve), if any."""
        if self.turner is not None and joint in ARM_JOINTS[self.turner.side]:
            return f"turn_valve ({self.turner.side} hand)"
        return None

    def cancel(self, hand: str | None = None) -> None:
        """Stop turning (with `hand`, only if that hand turns it): the hand lets go."""
        if self.turner is None or hand not in (None, self.turner.side):
            return
        self.turner.let_go()
        self.turner, self.status_word = None, "hand_off"

    def apply(self, step: int) -> str:
        """Turn this physics step's share; return the status."""
        if self.turner is None:
            return self.status_word
        status = self.turner.apply(step)
        if self.turner.done() or status.startswith("stalled"):
            self.turner.let_go()
            self.turner = None
            self.status_word = "idle" if not status.startswith("stalled") else status
        else:
            self.status_word = "turning"
        return self.status_word
