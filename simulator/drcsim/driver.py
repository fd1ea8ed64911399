"""The seated robot's hands on the vehicle: the left on the steering wheel, the right on levers.

The `drive` behaviour's parameters are targets for these limbs: the left hand holds the
steering wheel's rim and the arm turns it (hand over hand past the arm's stroke), the right
hand takes the hand brake or the F/N/R switch in turn and moves it. The vehicle responds
only to where the interfaces are (driving.py).
"""

from __future__ import annotations

from drcsim.assists import Grasps
from drcsim.control import JointController
from drcsim.driving import DIRECTIONS, VehicleDrive
from drcsim.handles import TOLERANCE, Handle, Turner, set_friction
from drcsim.models.vehicle import INTERFACES
from drcsim.reach import ARM_JOINTS, REACH_EVERY
from drcsim.scene import Scene

WHEEL_RIM = 0.18  # the steering wheel's radius, metres
LEVER_GRIP = 0.1  # from a lever's pivot to where the hand holds it
FRICTION = {"steering_wheel": 2.0, "hand_brake": 6.0, "fnr_switch": 3.0}  # N m
# The left hand works the wheel's upper left quarter (angle about the column from the left,
# +y, upwards) and strokes this far either side before taking the rim again.
WHEEL_HOME = 0.7
WHEEL_STROKE = 0.9
LEVERS = ("fnr_switch", "hand_brake")


class DriverLimbs:
    """Moves the steering wheel, hand brake and F/N/R switch with the seated robot's arms."""

    def __init__(
        self,
        scene: Scene,
        controller: JointController,
        grasps: Grasps,
        drive: VehicleDrive | None,
    ) -> None:
        self.scene, self.controller, self.grasps, self.drive = scene, controller, grasps, drive
        self.handles: dict[str, Handle] = {}
        self.targets = {"steering_wheel": 0.0, "hand_brake": 0.0, "fnr_switch": 0.0}
        self.wheel: Turner | None = None
        self.lever: Turner | None = None
        self.active: set[str] = set()  # the hands driving now
        if scene.vehicle is None:
            return
        for name in ("steering_wheel", *LEVERS):
            rim = name == "steering_wheel"
            axis, u = ((1, 0, 0), (0, 1, 0)) if rim else ((0, 1, 0), (0, 0, 1))
            handle = Handle(
                name,
                scene.vehicle,
                scene.vehicle_joints[name],
                axis,
                u,
                WHEEL_RIM if rim else LEVER_GRIP,
                rim,
            )
            self.handles[name] = handle
            grasps.handles.append(handle)
            set_friction(scene, handle, FRICTION[name])

    def set_targets(
        self, steering_wheel: float, throttle: float, brake: float, hand_brake: bool, direction: str
    ) -> None:
        """Set where the limbs put each interface (pedal fractions 0..1)."""
        assert self.drive is not None
        wheel = INTERFACES["steering_wheel"]
        self.targets["steering_wheel"] = min(max(steering_wheel, wheel.lower), wheel.upper)
        self.targets["hand_brake"] = INTERFACES["hand_brake"].upper if hand_brake else 0.0
        self.targets["fnr_switch"] = DIRECTIONS[direction]
        self.drive.set_pedals(throttle, brake)
        self.active = {"left", "right"}

    def owner(self, joint: str) -> str | None:
        """Return the behaviour owning `joint` (an arm driving), if any."""
        for side in self.active:
            if joint in ARM_JOINTS[side]:
                return f"drive ({side} hand)"
        return None

    def stop(self, side: str | None = None) -> None:
        """Take the hands (or one) off the controls."""
        for hand in ("left", "right"):
            if side not in (None, hand) or hand not in self.active:
                continue
            turner = self.wheel if hand == "left" else self.lever
            if turner is not None:
                turner.let_go()
            if hand == "left":
                self.wheel = None
            else:
                self.lever = None
            self.active.discard(hand)

    def apply(self, step: int) -> None:
        """Run this physics step's share of both hands."""
        if "left" in self.active:
            if self.wheel is None or self.wheel.status.startswith("stalled"):
                self.wheel = Turner(
                    self.scene,
                    self.controller,
                    self.grasps,
                    self.handles["steering_wheel"],
                    "left",
                    WHEEL_HOME,
                    WHEEL_STROKE,
                )
            self.wheel.goal = self.targets["steering_wheel"]
            self.wheel.apply(step)
        if "right" in self.active:
            if step % REACH_EVERY == 0:
                self._next_lever()
            if self.lever is not None:
                self.lever.apply(step)

    def _next_lever(self) -> None:
        """Keep the right hand on the lever it moves until done, then take the next one."""
        if self.lever is not None:
            self.lever.goal = self.targets[self.lever.handle.name]
        if self.lever is not None and not (
            self.lever.done() or self.lever.status.startswith("stalled")
        ):
            return
        pending = [
            name
            for name in LEVERS
            if abs(self.handles[name].angle(self.scene) - self.targets[name]) > TOLERANCE
        ]
        if not pending:
            return
        if self.lever is not None:
            if self.lever.handle.name == pending[0] and not self.lever.status.startswith("stall"):
                return
            self.lever.let_go()
        self.lever = Turner(
            self.scene, self.controller, self.grasps, self.handles[pending[0]], "right"
        )
        self.lever.goal = self.targets[pending[0]]

    def status(self) -> dict[str, str]:
        """Return what each hand does."""
        out = {}
        if self.wheel is not None:
            out["steering_wheel"] = self.wheel.status
        if self.lever is not None:
            out[self.lever.handle.name] = self.lever.status
        return out
