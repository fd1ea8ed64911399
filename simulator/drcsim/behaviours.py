"""VRC-style behaviours: stand, walk to a pose, reach, grasp/release, vehicle, valve."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from drcsim.assists import Coupling, Grasps, Seat
from drcsim.control import JointController
from drcsim.driver import DriverLimbs
from drcsim.driving import VehicleDrive
from drcsim.errors import CommandError
from drcsim.gait import GaitParameters
from drcsim.models import humanoid
from drcsim.reach import ARM_JOINTS, REACH_EVERY, Reach
from drcsim.scene import Scene
from drcsim.valve import Valve
from drcsim.walker import Walker

GAIT_KEYS = ("step_length", "step_height", "step_time", "double_support", "stance_width")
LEG_JOINTS = [s.name for s in humanoid.BODY_JOINTS if "_leg_" in s.name]
# The neck is the team's even while the walker holds the body (as BDI's library left Atlas's
# neck and arms to the user): pointing the head is how a team looks around.
TRUNK_JOINTS = ["back_bkz", "back_bky", "back_bkx"]
# What a fallen robot may still be told: let go of its joints, arms and hands.
WHILE_DOWN = ("none", "arm_rest", "release")


class Behaviours:
    """The behaviour layer between team commands and the joint controller."""

    def __init__(
        self,
        scene: Scene,
        controller: JointController,
        drive: VehicleDrive | None,
        assists: dict[str, float],
    ) -> None:
        self.scene, self.controller, self.drive = scene, controller, drive
        self.client = scene.client
        self.grasps = Grasps(scene, controller)
        self.seat = Seat(scene, controller, drive)
        self.valve = Valve(scene, controller, self.grasps)
        self.driver = DriverLimbs(scene, controller, self.grasps)
        self.coupling = Coupling(
            scene,
            self.grasps,
            assists.get("coupling_distance", 0.08),
            int(assists.get("coupling_hold_s", 0.2) * 100),
        )
        self.mode = "stand"
        self.walk_status = "idle"
        self.reaches: dict[str, Reach] = {}
        self.steps = 0
        body = LEG_JOINTS + TRUNK_JOINTS
        self._body_slots = np.array([controller.slot[name] for name in body])
        self._sit_targets = np.array([humanoid.SIT_POSTURE.get(n, 0.0) for n in body])
        controller.reset_to(humanoid.STAND_POSTURE)
        # The run starts with the robot standing on its feet, balanced by the walker through
        # its leg joints: nothing else holds it up.
        self.walker = Walker(scene, controller)

    # -- joint ownership ----------------------------------------------------------------------
    def owner(self, joint: str) -> str | None:
        """Return the behaviour that drives `joint` now (it refuses team commands), if any."""
        if joint in LEG_JOINTS or joint in TRUNK_JOINTS:
            return self.mode if self.mode in ("stand", "walk", "seated") else None
        for side, reach in self.reaches.items():
            if joint in ARM_JOINTS[side]:
                return f"reach ({reach.side} hand)"
        return self.valve.owner(joint) or self.driver.owner(joint)

    def check_free(self, joints: list[str]) -> None:
        """Raise CommandError naming every joint in `joints` that a behaviour owns."""
        owned = [(name, owner) for name in joints if (owner := self.owner(name)) is not None]
        if owned:
            listed = ", ".join(f"{name} (owned by {owner})" for name, owner in owned)
            raise CommandError(
                f"refused: {listed}; send behaviour 'none' (or 'arm_rest' for an arm) "
                "to take the joints back"
            )

    # -- commands -------------------------------------------------------------------------
    def command(self, name: str, params: dict[str, Any], fallen: bool) -> dict[str, Any]:
        """Start behaviour `name`; return details for the reply; raise CommandError if refused."""
        if self.seat.seated and name in ("stand", "walk", "none"):
            raise CommandError(f"{name} is not possible in the vehicle (exit_vehicle first)")
        if fallen and name not in WHILE_DOWN:
            raise CommandError(
                f"{name} is not possible: the robot is down (drcsim offers no get-up, nor did "
                "the VRC's behaviour library); only the team's own joint commands can stand it up"
            )
        if name == "none":
            self._release_legs()
            self.mode = "none"
            self.reaches.clear()
        elif name in ("stand", "walk"):
            self._balance(name, params, fallen)
        elif name == "reach":
            side = params["hand"]
            self._free_arm(side)
            self.reaches[side] = Reach(
                self.scene,
                self.controller,
                side,
                params["target"],
                bool(params.get("tool", False)),
                self.grasps,
                str(params.get("frame", "world")),
            )
        elif name == "arm_rest":
            self.reaches.pop(params["hand"], None)
            self._free_arm(params["hand"])
            posture = humanoid.SIT_POSTURE if self.seat.seated else humanoid.STAND_POSTURE
            self.controller.set_positions(
                {j: posture.get(j, 0.0) for j in ARM_JOINTS[params["hand"]]}
            )
        elif name == "grasp":
            grasped = self.grasps.close(params["hand"])
            return {"grasped": grasped, **({} if grasped else {"note": "closed on nothing"})}
        elif name == "release":
            self._free_arm(params["hand"])
            self.grasps.open(params["hand"])
        elif name == "enter_vehicle":
            self.seat.enter()
            self._release_legs()
            self.mode = "seated"
            self.reaches.clear()
        elif name == "exit_vehicle":
            self.seat.check_exit()
            self.driver.stop()
            self.seat.exit()
            self._hand_to_walker(reset=True)
            self.mode, self.walk_status = "stand", "idle"
        elif name == "drive":
            if not self.seat.seated or self.drive is None:
                raise CommandError("drive needs the robot in the driver seat")
            self.reaches.clear()
            self.driver.set_targets(
                float(params.get("steering_wheel", 0.0)),
                float(params.get("throttle", 0.0)),
                float(params.get("brake", 0.0)),
                bool(params.get("hand_brake", False)),
                str(params.get("direction", "neutral")),
            )
        elif name == "turn_valve":
            # Started first: a refused turn (hand not at the valve) leaves the reach as it was.
            self.valve.start(params["hand"], float(params.get("angle", 2 * math.pi)))
            self.reaches.pop(params["hand"], None)
        else:
            raise CommandError(f"unknown behaviour {name!r}")
        return {}

    def _free_arm(self, side: str) -> None:
        """Stop the valve or driving behaviour that uses this arm (its hand lets go)."""
        self.valve.cancel(side)
        self.driver.stop(side)

    @property
    def walker_on(self) -> bool:
        """Return whether the walker holds the legs (standing or walking)."""
        return self.mode in ("stand", "walk")

    def _release_legs(self) -> None:
        """Take the legs from the walker (stock gains): the team's commands or the seat own them."""
        if self.walker_on:
            self.walker.release()

    def _hand_to_walker(self, reset: bool) -> None:
        """Give the legs to the walker (before the mode says so); `reset` takes the robot as
        it stands now."""
        if not self.walker_on:
            self.walker.use_gains()
        if reset or not self.walker_on:
            self.walker.reset()

    def _balance(self, name: str, params: dict[str, Any], fallen: bool) -> None:
        """Stand or walk with the walker: only the leg joints hold the robot up."""
        # Standing takes the robot as it stands now (it may have been moved: the seat, a
        # team's own joint control); a walk in progress is not cut off mid-step.
        self._hand_to_walker(reset=self.walker.status != "walking")
        if name == "stand":
            self.mode, self.walk_status = "stand", "idle"
            return
        gait = {k: float(params[k]) for k in GAIT_KEYS if k in params}
        goal = params["pose"]
        self.walker.redirect((goal[0], goal[1], goal[2]), GaitParameters(**gait))
        self.mode, self.walk_status = "walk", "walking"

    def fall(self) -> None:
        """Stop every behaviour: the robot is down (a fall ends what it was doing)."""
        self.valve.cancel()
        self.driver.stop()
        self.reaches.clear()
        if self.mode == "walk":
            self.walk_status = f"fell ({self.walk_status})"
        if self.mode != "seated":
            self._release_legs()
            self.mode = "none"

    # -- per step -------------------------------------------------------------------------
    def apply(self) -> None:
        """Run this physics step's share of every active behaviour."""
        self.steps += 1
        if self.mode in ("stand", "walk"):
            self.walker.apply()
            if self.mode == "walk":
                self.walk_status = self.walker.describe()
                if self.walker.status != "walking":
                    self.mode = "stand"
        elif self.mode == "seated":
            self.controller.set_slot_positions(self._body_slots, self._sit_targets)
        for reach in self.reaches.values():
            if self.steps % REACH_EVERY == 0:
                reach.update()
            reach.apply()
        self.valve.apply(self.steps)
        self.driver.apply(self.steps)
        if self.drive is not None:
            self.drive.apply()

    # -- status -------------------------------------------------------------------------------
    def status(self) -> dict[str, Any]:
        """Return what each behaviour is doing."""
        return {
            "mode": self.mode,
            "walk": self.walk_status,
            "reach": {side: reach.status for side, reach in self.reaches.items()},
            "held": {hand: name for hand, (_, name) in self.grasps.held.items()},
            "seated": self.seat.seated,
            "hose_connected": self.grasps.hose_connected,
            "valve": self.valve.status_word,
            "drive": self.driver.status(),
        }
