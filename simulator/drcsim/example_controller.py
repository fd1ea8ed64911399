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
from drcsim.posts import clusters, gate_posts, post_correction, post_returns

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
# A walk may take this long (simulated s) plus its distance at the slowest speed expected
# (the walker in deep mud); past it the controller walks there again or moves on.
WALK_BASE_S = 30.0
WALK_SLOWEST = 0.05  # m/s
# Moves shorter than the walker's 0.6 m are stepped without turning round (backwards or
# sideways): a leg of a shuffle stays below that.
SHUFFLE_LEG = 0.5
# ...in short steps: a sideways leg in the walker's 0.25 m steps ends with the body still
# swaying out over the last foot (it fell that way at the standpipe).
SHUFFLE_GAIT = {"step_length": 0.15}
# The seat assist puts the robot in the seat within 1.5 m of the driver door: stand this
# far out from the door (the briefing's door is off by up to 0.25 m), clear of the body.
DOOR_STANDOFF = 0.5
# The hose hangs 0.75 m behind the coupler held 0.45 m ahead of the pelvis: back away until
# it has slid off the table (half 0.6 m long) before turning, or it snags on the table.
TABLE_CLEAR = 1.9
TABLE_STANDOFF = 0.9  # m from the table's middle to the pelvis facing it (0.3 from its edge)
# How far from a patch of terrain the careful controller's path round it keeps (m).
HAZARD_GAP = 0.4
# The driver seat (where the seated pelvis is) lies this far behind the vehicle's middle and
# left of its centre line (m): the vehicle is steered by its middle, not by the driver.
SEAT_BEHIND, SEAT_LEFT = 0.15, 0.3
# Carrying the hose to the standpipe the hand is this high over the pelvis (m): the hose
# then passes under the valve wheel (its rim 1.18 m up), which it met carried at 0.35.
CARRY_LOW = 0.2


# Looking round for the posts: half a turn of the lidar's spindle (0.5 rad/s) brings every
# scan plane by once.
LOOK_S = 6.5
# Out of the vehicle, how far (m) to walk on along its side before turning to the finish: the
# vehicle's front is about 1.4 m ahead of the driver door (its middle 0.15 m ahead of the
# seat, 2.4 m long with the wheels' reach).
FRONT_CLEAR = 2.3
# ...and how much further out from its side (m): the door leaves 0.7 m, and walking along at
# that, still 0.3 m off the estimate's line, it fell beside the front wheel.
SIDE_GAP = 0.5


class Down(ClientError):
    """The robot fell and the controller does not get it up: it gives up the run."""


def vehicle_middle(px: float, py: float, yaw: float) -> tuple[float, float]:
    """The vehicle's middle from the seated pelvis (SEAT_BEHIND behind it, SEAT_LEFT left)."""
    c, s = math.cos(yaw), math.sin(yaw)
    return px + SEAT_BEHIND * c + SEAT_LEFT * s, py + SEAT_BEHIND * s - SEAT_LEFT * c


def finish_legs(
    x: float, y: float, yaw: float, gate: tuple[float, float, float]
) -> list[tuple[float, float, float]]:
    """The legs from beside the driver door (at x, y facing yaw) to just before the gate.

    The vehicle is on the right, its front about 1.4 m ahead: first on along its side until
    FRONT_CLEAR ahead (clear of the front) and SIDE_GAP out, if that leaves 0.5 m before the
    gate line (else on to 0.5 m before it, not out towards a post); then across to the gate's
    middle line, up to 1 m before the gate and never back round the vehicle's front corner (a
    diagonal from beside the door met it there). Out less than FRONT_CLEAR before the gate
    line (the vehicle's front at it or through), straight to 1 m before the gate.
    """
    gx, gy, gyaw = gate
    c, s = math.cos(gyaw), math.sin(gyaw)
    before = (gx - x) * c + (gy - y) * s  # how far before the gate line the robot is
    if before < FRONT_CLEAR:  # the vehicle's front at the gate line, or past it
        return [(gx - c, gy - s, gyaw)]
    # ...and out to the left as it goes, SIDE_GAP further from the vehicle's side, when there
    # is room; else on only to 0.5 m before the gate line and not out (towards a post).
    on, out = (FRONT_CLEAR, SIDE_GAP) if before >= FRONT_CLEAR + 0.5 else (before - 0.5, 0.0)
    wx = x + on * math.cos(yaw) - out * math.sin(yaw)
    wy = y + on * math.sin(yaw) + out * math.cos(yaw)
    short = max(0.5, min(1.0, (gx - wx) * c + (gy - wy) * s))
    return [(wx, wy, yaw), (gx - short * c, gy - short * s, gyaw)]


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
    approach_tries = 2  # walks again when a walk ends short of its goal
    straight = False  # True: straight at every goal (also the door), no backing-away legs
    avoid: tuple[str, ...] = ()  # kinds of terrain (the briefing's) walked round in task 2
    gait: dict[str, float] = {}  # the walker's defaults

    def __init__(
        self,
        client: CommandAPI,
        log: Log = lambda _: None,
        timeout_s: float = 600.0,
    ):
        self.client = client
        self.log = log
        self.info = client.hello()
        self.lockstep = bool(self.info["lockstep"])
        self.deadline = time.monotonic() + timeout_s
        self.final_score: dict[str, Any] | None = None
        self.scans: list[dict[str, Any]] = []  # lidar scans received while looking
        self.gave_up: str | None = None
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
            if topic == "lidar":
                self.scans.append(message)
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
    def walk(
        self, x: float, y: float, yaw: float, limit_s: float | None = None, **gait: float
    ) -> dict[str, Any]:
        """Walk to a pose; after a short stop walk again; after a fall give up (no get-up)."""
        approaches = self.approach_tries
        while True:
            state = self.client.state()
            falls = state["score"]["falls"]
            here = state["pelvis"]["position"]
            limit = limit_s or WALK_BASE_S + math.hypot(x - here[0], y - here[1]) / WALK_SLOWEST
            self.client.behaviour("walk", pose=[x, y, yaw], **self.walk_params(**gait))

            def over(s: dict[str, Any], falls: int = falls) -> bool:  # fell, or stopped
                walk = str(s["behaviour"]["walk"])
                return s["score"]["falls"] > falls or not walk.startswith("walking")

            state = self.until(over, limit)
            if state["score"]["ended"]:
                return state
            if state["score"]["falls"] > falls:
                raise Down(f"fell walking to {x:.2f} {y:.2f} and does not get up")
            status = str(state["behaviour"]["walk"])
            if status == "done" or approaches <= 0:
                return state
            approaches -= 1  # ended short (blocked, or still walking at the limit): again
            self.log(f"walk to {x:.2f} {y:.2f} ended {status!r}: walking there again")

    def walk_params(self, **gait: float) -> dict[str, Any]:
        """Return the walk behaviour's gait parameters (this controller's, `gait`)."""
        return {**self.gait, **gait}

    def shuffle(self, x: float, y: float, yaw: float) -> dict[str, Any]:
        """Step to a pose nearby in short legs, backwards or sideways, without turning round."""
        state = self.client.state()
        px, py = state["pelvis"]["position"][:2]
        legs = max(1, math.ceil(math.hypot(x - px, y - py) / SHUFFLE_LEG))
        for leg in range(1, legs + 1):
            state = self.walk(
                px + (x - px) * leg / legs, py + (y - py) * leg / legs, yaw, **SHUFFLE_GAIT
            )
        return state

    def look_for_posts(self, gates: dict[str, Any]) -> tuple[float, float]:
        """Stand still and look round with the lidar; return the estimate's correction.

        The estimate's position drifts (its yaw drifts, and odometry turns by it): after a
        drive it may be 2 m off. The gates' posts stand where the briefing says, to 0.25 m:
        the shift that brings the posts the lidar sees onto the briefing's corrects it
        (nothing when the client has no topics or no two posts agree).
        """
        subscribe = getattr(self.client, "subscribe", None)
        receive = getattr(self.client, "receive", None)
        if subscribe is None or receive is None:
            self.log("no lidar on this client: walking on the estimate")
            return 0.0, 0.0
        subscribe("lidar")
        self.scans = []
        returns: list[tuple[float, float]] = []
        state = self.client.state()
        end = state["t"] + LOOK_S
        while state["t"] < end and not state["score"]["ended"]:
            state = self.advance(0.25)
            while self.lockstep and (received := receive(0.05)) is not None:
                if received[0] == "lidar":
                    self.scans.append(received[1])
            for scan in self.scans:
                returns += post_returns(scan, state["pelvis"])
            self.scans = []
        getattr(self.client, "unsubscribe", lambda *_: None)("lidar")
        seen = clusters(returns)
        shift = post_correction(seen, gate_posts(gates))
        self.log(f"posts seen at {[(round(x, 2), round(y, 2)) for x, y in seen]}: shift {shift}")
        return shift or (0.0, 0.0)

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
        except Down as exc:
            self.gave_up = str(exc)
            self.log(f"gave up: {exc}")
        except ClientError as exc:
            if "the robot is down" in str(exc):  # it fell doing something else than walking
                self.gave_up = f"fell and does not get up ({exc})"
                self.log(f"gave up: {self.gave_up}")
            # A real failure, not a command refused (or the server going away) after the end.
            elif self.final_score is None and not self.client.state()["score"]["ended"]:
                raise
        if self.final_score is None:
            self.final_score = dict(self.client.state()["score"])
        self.log(f"score {self.final_score}")
        return self.final_score

    def walking(self, course: dict[str, Any]) -> None:
        """Task 2: walk through each gate in turn, around the terrain it avoids (`avoid`)."""
        hazards = [p for p in course.get("terrain", {}).values() if p["kind"] in self.avoid]
        for name in sorted(course["gates"]):
            gx, gy, gyaw = course["gates"][name]["pose"]
            here = self.client.state()["pelvis"]["position"]
            for patch in hazards:
                if here[0] < patch["min"][0] and patch["max"][0] < gx:
                    self.around(patch, gy)
            x, y = gx + self.walk_past * math.cos(gyaw), gy + self.walk_past * math.sin(gyaw)
            for patch in hazards:  # stop short of a patch beyond the gate, to go round it
                if gx < patch["min"][0] < x + HAZARD_GAP:
                    x, y = patch["min"][0] - HAZARD_GAP, gy
            state = self.walk(x, y, gyaw)
            self.log(f"{name}: {state['score']}")
            if state["score"]["ended"]:
                return

    def around(self, patch: dict[str, Any], then_y: float) -> None:
        """Walk round a patch of terrain (the course runs along +x), on its nearer side."""
        (x0, y0), (x1, y1) = patch["min"], patch["max"]
        y = self.client.state()["pelvis"]["position"][1]
        side = y1 + HAZARD_GAP if abs(y - y1) <= abs(y - y0) else y0 - HAZARD_GAP
        self.log(f"round the {patch['kind']} at y {side:.1f}")
        # Out and back in sideways, facing along the course: no square turns (it fell
        # turning in place there, out at the near corner and back in at the far one).
        self.shuffle(x0 - HAZARD_GAP, side, 0.0)
        self.walk(x1 + HAZARD_GAP, side, 0.0)
        self.shuffle(x1 + HAZARD_GAP, then_y, 0.0)

    def driving(self, course: dict[str, Any]) -> None:
        """Task 1: get in, drive through both gates, stop, get out, walk to the finish."""
        self.get_in(course["vehicle"])
        self.log(f"seated: {self.advance(0.5)['score']}")
        for name in ("gate_1", "gate_2"):
            gx, gy, gyaw = course["gates"][name]["pose"]
            self._drive_through(gx + 2.5 * math.cos(gyaw), gy + 2.5 * math.sin(gyaw))
            self.log(f"{name}: {self.client.state()['score']}")
        self.client.behaviour("drive", direction="neutral", brake=1.0, hand_brake=True)
        self.advance(2.0)
        for _ in range(10):  # still rolling after 2 s of braking: wait until it stands
            if self.client.try_behaviour("exit_vehicle").get("ok"):
                break
            self.advance(1.0)
        else:
            self.client.behaviour("exit_vehicle")
        state = self.advance(2.0)  # let it settle on its feet beside the door
        gx, gy, gyaw = course["gates"]["gate_3"]["pose"]
        c, s = math.cos(gyaw), math.sin(gyaw)
        if not self.straight:
            # Where it truly is, by the gates' posts (the estimate is ~2 m off after a drive);
            # then out along the vehicle's side, past its front (braking by foot, it may have
            # come to rest close to the finish), and square in front of the finish gate.
            dx, dy = self.look_for_posts(course["gates"])
            state = self.client.state()
            ex, ey = state["pelvis"]["position"][0] + dx, state["pelvis"]["position"][1] + dy
            for leg in finish_legs(ex, ey, _yaw(state["pelvis"]["orientation"]), (gx, gy, gyaw)):
                self.walk(*leg)
        past = self.walk_past
        self.walk(gx + past * c, gy + past * s, gyaw)

    def get_in(self, vehicle: dict[str, Any]) -> None:
        """Walk to the driver door (from behind, along the side) and take the seat assist."""
        door, car_yaw = vehicle["driver_door"], vehicle["pose"][2]
        c, s = math.cos(car_yaw), math.sin(car_yaw)
        out = 0.0 if self.straight else DOOR_STANDOFF
        stand = (door[0] - s * out, door[1] + c * out)
        if not self.straight:  # come to the door from the side, not through the vehicle
            self.walk(stand[0] - 2.5 * c, stand[1] - 2.5 * s, car_yaw)
        self.walk(*stand, car_yaw)
        if self.straight:
            self.client.behaviour("enter_vehicle")  # refused if it never got to the door
            return
        refused = self.client.try_behaviour("enter_vehicle").get("error")
        if refused is None:
            return
        self.log(f"{refused}: walking to the door itself")
        self.walk(door[0], door[1], car_yaw)
        self.client.behaviour("enter_vehicle")

    def _drive_through(self, tx: float, ty: float, limit_s: float = 60.0) -> None:
        state = self.client.state()
        start = state["t"]
        while state["t"] - start < limit_s and not state["score"]["ended"]:
            px, py, _ = state["pelvis"]["position"]
            yaw = _yaw(state["pelvis"]["orientation"])
            px, py = vehicle_middle(px, py, yaw)
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
        # Behind the coupler, but clear of the table's edge: an arm or knee on it tips the
        # robot over backwards as it stops.
        self.walk(min(hose[0] - 0.45, table_x - TABLE_STANDOFF), hose[1] + 0.3, 0.0)
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
        state = self.advance(0.5)
        self.log(f"lifted: {state['score']}")
        if not self.straight:  # straight back, drawing the hose off the table lengthwise
            y = state["pelvis"]["position"][1]
            self.shuffle(min(state["pelvis"]["position"][0], table_x - TABLE_CLEAR), y, 0.0)
        pipe_yaw = course["standpipe"]["pose"][2]

        def near(point: list[float], forward: float, left: float) -> tuple[float, float]:
            c, s = math.cos(pipe_yaw), math.sin(pipe_yaw)
            return (point[0] + c * forward - s * left, point[1] + s * forward + c * left)

        gx, gy = near(inlet, -0.45, 0.3)
        if not self.straight:
            # Square to the standpipe and sideways first, then straight at it: no long
            # diagonal with the hose swinging from the hand (on one foot, its swing spun the
            # stance foot and the robot fell), no turning with it at the end.
            here = self.client.state()["pelvis"]["position"]
            ahead = (gx - here[0]) * math.cos(pipe_yaw) + (gy - here[1]) * math.sin(pipe_yaw)
            self.shuffle(gx - ahead * math.cos(pipe_yaw), gy - ahead * math.sin(pipe_yaw), pipe_yaw)
            self.reach("right", [0.45, -0.3, CARRY_LOW], frame="pelvis")
        self.walk(gx, gy, pipe_yaw)
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
        # Sideways along the standpipe to the valve, without turning round.
        (self.walk if self.straight else self.shuffle)(*near(valve, -0.5, -0.3), pipe_yaw)
        self.reach("left", [*near(valve, -0.12, 0.0), valve[2]])
        self.client.behaviour("turn_valve", hand="left", angle=3.5)
        self.until(lambda s: s["behaviour"]["valve"] != "turning", 30.0)
