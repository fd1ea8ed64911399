"""An example team controller: drives each task through the client library only.

It uses the course briefing from the hello reply (where the vehicle, gates, table, hose and
standpipe roughly are) and feels around those positions with the hand where precision
matters (grasping the coupler, finding the inlet), and the server's behaviours for balance,
walking and reaching.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

from drcsim.client import SimClient
from drcsim.commands import CommandAPI
from drcsim.errors import ClientError

Log = Callable[[str], None]
# Offsets (m) tried in turn around a roughly known position until the hand finds the object.
SEARCH = [(0.0, 0.0), (0.06, 0.0), (-0.06, 0.0), (0.0, 0.06), (0.0, -0.06)]
SEARCH += [(0.06, 0.06), (-0.06, -0.06), (0.06, -0.06), (-0.06, 0.06)]


def grid(spacing: float, radius: float) -> list[tuple[float, float]]:
    """Return the points of a square grid within `radius` of the origin, nearest first."""
    n = int(radius / spacing)
    points = [(i * spacing, j * spacing) for i in range(-n, n + 1) for j in range(-n, n + 1)]
    inside = [(round(x, 3), round(y, 3)) for x, y in points if math.hypot(x, y) <= radius]
    return sorted(inside, key=lambda p: (round(math.hypot(*p), 3), math.atan2(p[1], p[0])))


# Where the hand closes to feel for the coupler: the palm must be within 5 cm of its axis
# (the README's grasp); wherever the coupler lies within the briefing's 8 cm and however it
# is turned, a grid 5 cm apart has a point within 3.6 cm (5/sqrt 2) of its middle.
GRASP_SEARCH = grid(0.05, 0.115)


def _yaw(orientation: list[float]) -> float:
    x, y, z, w = orientation
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


class ExampleController:
    """Runs one task to completion (or as far as it gets) over a SimClient or a LocalClient."""

    # What the reference controllers (drcsim.controllers) vary: how hard they drive, how
    # they steer, how far past a gate they aim, where they feel for objects, and whether
    # they come to the driver door from the side.
    throttle = 0.7
    steer_gain = 7.5
    walk_past = 1.0
    search = SEARCH
    grasp_search = GRASP_SEARCH
    approach_door = True
    walk_tries = 2
    gait: dict[str, float] = {}  # the walker's defaults (used with balance "joints")

    def __init__(
        self,
        client: CommandAPI,
        log: Log = lambda _: None,
        timeout_s: float = 600.0,
        balance: str = "harness",
    ):
        self.balance = balance
        self.client = client
        self.log = log
        self.info = client.hello()
        self.lockstep = bool(self.info["lockstep"])
        self.deadline = time.monotonic() + timeout_s
        self.final_score: dict[str, Any] | None = None
        if not self.lockstep and isinstance(client, SimClient):
            client.subscribe("clock", "score")

    # -- time -------------------------------------------------------------------------------
    def advance(self, seconds: float) -> dict[str, Any]:
        """Let `seconds` of simulated time pass; return the state after them."""
        if self.lockstep:
            return self.client.step(max(1, round(seconds / self.info["timestep"])))
        # A real-time server advances on its own: wait for its clock, or for the run's end.
        assert isinstance(self.client, SimClient)
        target = self.client.state()["t"] + seconds
        while self.final_score is None:
            remaining = self.deadline - time.monotonic()
            if remaining <= 0:
                raise ClientError("example controller ran out of wall time")
            received = self.client.receive(min(remaining, 1.0))
            if received is None:
                continue
            topic, message = received
            if topic == "clock" and message["t"] >= target:
                return self.client.state()
            if topic == "score" and message["event"] == "run_end":
                self.final_score = {
                    "checkpoints": message["score"],
                    "falls": message["falls"],
                    "ended": True,
                    "reason": message["reason"],
                }
        return {"t": target, "score": self.final_score, "behaviour": {}}

    def until(
        self, done: Callable[[dict[str, Any]], bool], limit_s: float, poll_s: float = 0.25
    ) -> dict[str, Any]:
        """Advance until `done(state)` or the run ends or `limit_s` simulated seconds pass."""
        state = self.client.state()
        start = state["t"]
        while not state["score"]["ended"] and not done(state) and state["t"] - start < limit_s:
            state = self.advance(poll_s)
        return state

    # -- building blocks --------------------------------------------------------------------
    def walk(self, x: float, y: float, yaw: float, limit_s: float = 90.0) -> dict[str, Any]:
        """Walk to a pose and wait until the walk ends; after a fall, get up and try again."""
        for _ in range(self.walk_tries):
            falls = self.client.state()["score"]["falls"]
            self.client.behaviour("walk", pose=[x, y, yaw], **self.walk_params())
            state = self.until(
                lambda s: not str(s["behaviour"]["walk"]).startswith("walking"), limit_s
            )
            if state["score"]["ended"] or state["score"]["falls"] == falls:
                return state
            self.log(f"fell walking to {x:.2f} {y:.2f}: getting up")
            self.client.behaviour("stand", balance=self.balance)  # the recovery assist
            self.advance(1.0)
        return state

    def walk_params(self) -> dict[str, Any]:
        """Return the walk behaviour's balance and gait parameters for this controller."""
        if self.balance == "harness":
            return {}
        return {"balance": self.balance, **self.gait}

    def reach(
        self, hand: str, target: list[float], limit_s: float = 4.0, **params: Any
    ) -> dict[str, Any]:
        """Reach and wait until the hand (or held tool) is there."""
        self.client.behaviour("reach", hand=hand, target=target, **params)
        return self.until(
            lambda s: s["behaviour"]["reach"].get(hand) == "reached", limit_s, poll_s=0.1
        )

    # -- tasks ------------------------------------------------------------------------------
    def run(self) -> dict[str, Any]:
        """Run the task of the server's world; return the final score."""
        task = {
            "vrc_task_1": self.driving,
            "vrc_task_2": self.walking,
            "vrc_task_3": self.manipulation,
        }[self.info["world"]]
        try:
            task(self.info["course"])
        except ClientError:
            if self.final_score is None:
                raise  # a real failure, not the server going away after the run ended
        if self.final_score is None:
            self.final_score = dict(self.client.state()["score"])
        self.log(f"score {self.final_score}")
        return self.final_score

    def walking(self, course: dict[str, Any]) -> None:
        """Task 2: walk through each gate in turn."""
        for name in sorted(course["gates"]):
            gx, gy, gyaw = course["gates"][name]["pose"]
            past = self.walk_past
            state = self.walk(gx + past * math.cos(gyaw), gy + past * math.sin(gyaw), gyaw)
            self.log(f"{name}: {state['score']}")
            if state["score"]["ended"]:
                return

    def driving(self, course: dict[str, Any]) -> None:
        """Task 1: get in, drive through both gates, stop, get out, walk to the finish."""
        door = course["vehicle"]["driver_door"]
        car_yaw = course["vehicle"]["pose"][2]
        if self.approach_door:  # come to the door from the side, not through the vehicle
            c, s = math.cos(car_yaw), math.sin(car_yaw)
            self.walk(door[0] - 2.5 * c, door[1] - 2.5 * s, car_yaw)
        self.walk(door[0], door[1], car_yaw)
        self.client.behaviour("enter_vehicle")
        self.log(f"seated: {self.advance(0.5)['score']}")
        for name in ("gate_1", "gate_2"):
            gx, gy, gyaw = course["gates"][name]["pose"]
            self._drive_through(gx + 2.5 * math.cos(gyaw), gy + 2.5 * math.sin(gyaw))
            self.log(f"{name}: {self.client.state()['score']}")
        self.client.behaviour("drive", direction="neutral", brake=1.0, hand_brake=True)
        self.advance(2.0)
        self.client.behaviour("exit_vehicle")
        gx, gy, gyaw = course["gates"]["gate_3"]["pose"]
        # Out wide on the driver's side first: braking by foot, the vehicle may have come to
        # rest close to the finish, and a straight walk there would brush along its side.
        c, s = math.cos(gyaw), math.sin(gyaw)
        self.walk(gx - 2.0 * c - 1.5 * s, gy - 2.0 * s + 1.5 * c, gyaw)
        past = self.walk_past
        self.walk(gx + past * math.cos(gyaw), gy + past * math.sin(gyaw), gyaw)

    def _drive_through(self, tx: float, ty: float, limit_s: float = 60.0) -> None:
        state = self.client.state()
        start = state["t"]
        while state["t"] - start < limit_s and not state["score"]["ended"]:
            px, py, _ = state["pelvis"]["position"]
            yaw = _yaw(state["pelvis"]["orientation"])
            if (tx - px) * math.cos(yaw) + (ty - py) * math.sin(yaw) < 0.0:
                return  # the target is behind us: we are through
            error = math.atan2(ty - py, tx - px) - yaw
            error = (error + math.pi) % (2 * math.pi) - math.pi
            self.client.behaviour(
                "drive",
                direction="forward",
                throttle=self.throttle,
                steering_wheel=max(-3.0, min(3.0, self.steer_gain * error)),
            )
            state = self.advance(0.1)

    def manipulation(self, course: dict[str, Any]) -> None:
        """Task 3: pick up the hose, bring it to the inlet, connect it, turn the valve."""
        hose = course["hose"]["coupler"]
        inlet = course["standpipe"]["inlet"]
        valve = course["standpipe"]["valve"]
        table_x = course["table"]["pose"][0]
        self.walk(hose[0] - 0.45, hose[1] + 0.3, 0.0)
        # The briefing is rough: feel for the coupler around where it should be.
        for dx, dy in self.grasp_search:
            self.reach("right", [hose[0] - 0.25 + dx, hose[1] + dy, hose[2] + 0.3])
            self.reach("right", [hose[0] + dx, hose[1] + dy, hose[2] + 0.01])
            grasped = self.client.behaviour("grasp", hand="right").get("grasped")
            self.log(f"grasp at {dx:+.2f} {dy:+.2f}: {grasped}")
            if grasped:
                break
            self.client.behaviour("release", hand="right")
        self.reach("right", [0.45, -0.3, 0.35], frame="pelvis")
        self.log(f"lifted: {self.advance(0.5)['score']}")
        # Back away from the table before heading for the standpipe.
        side = -1.0 if inlet[1] < hose[1] else 1.0
        self.walk(table_x - 1.2, hose[1] + side * 1.0, 0.0)
        pipe_yaw = course["standpipe"]["pose"][2]

        def near(point: list[float], forward: float, left: float) -> tuple[float, float]:
            c, s = math.cos(pipe_yaw), math.sin(pipe_yaw)
            return (point[0] + c * forward - s * left, point[1] + s * forward + c * left)

        self.walk(*near(inlet, -0.45, 0.3), pipe_yaw)
        # Line the coupler up in front of the inlet, then push it home.
        for dx, dy in self.search:
            self.reach("right", [*near(inlet, -0.15 + dx, dy), inlet[2]], tool=True)
            self.reach("right", [*near(inlet, dx, dy), inlet[2]], tool=True, limit_s=6.0)
            state = self.advance(1.0)
            self.log(f"at the inlet {dx:+.2f} {dy:+.2f}: {state['score']}")
            if state["behaviour"].get("hose_connected") or state["score"]["ended"]:
                break
        self.reach("right", [0.3, -0.3, 0.0], frame="pelvis")
        self.client.behaviour("arm_rest", hand="right")
        self.walk(*near(valve, -0.5, -0.3), pipe_yaw)
        self.reach("left", [*near(valve, -0.12, 0.0), valve[2]])
        self.client.behaviour("turn_valve", hand="left", angle=3.5)
        self.until(lambda s: s["behaviour"]["valve"] != "turning", 30.0)
