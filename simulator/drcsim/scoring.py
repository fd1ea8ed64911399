"""Scoring from data: ordered checkpoints as conditions over observations, falls, run end."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from drcsim.errors import WorldError
from drcsim.models.props import GATE_DEPTH

FALL_HEIGHT = 0.6  # pelvis above the ground, metres
FALL_TILT = math.radians(45)
MAX_FALLS = 3


@dataclass(frozen=True)
class GateFrame:
    """A gate as scoring sees it: pose and opening width."""

    x: float
    y: float
    yaw: float
    width: float


@dataclass
class Observation:
    """What the scorer may look at: body positions, flags and named quantities."""

    positions: dict[str, tuple[float, float, float]]
    flags: dict[str, bool]
    quantities: dict[str, float]


def _through_gate(position: tuple[float, float, float], gate: GateFrame) -> bool:
    dx, dy = position[0] - gate.x, position[1] - gate.y
    c, s = math.cos(gate.yaw), math.sin(gate.yaw)
    along, across = c * dx + s * dy, -s * dx + c * dy
    return 0.0 <= along <= GATE_DEPTH and abs(across) <= gate.width / 2


def evaluate(condition: dict[str, Any], obs: Observation, gates: dict[str, GateFrame]) -> bool:
    """Return whether `condition` (a one-key mapping, see README) holds for `obs`."""
    if len(condition) != 1:
        raise WorldError(f"a condition has exactly one key, not {sorted(condition)}")
    ((kind, arg),) = condition.items()
    if kind == "all":
        return all(evaluate(part, obs, gates) for part in arg)
    if kind == "any":
        return any(evaluate(part, obs, gates) for part in arg)
    if kind == "flag":
        return bool(obs.flags.get(arg, False))
    if kind == "not_flag":
        return not obs.flags.get(arg, False)
    if kind == "at_least":
        return obs.quantities.get(arg["quantity"], -math.inf) >= float(arg["value"])
    if kind == "at_most":
        return obs.quantities.get(arg["quantity"], math.inf) <= float(arg["value"])
    if kind == "through_gate":
        if arg["gate"] not in gates or arg["body"] not in obs.positions:
            raise WorldError(f"through_gate names unknown gate or body: {arg}")
        return _through_gate(obs.positions[arg["body"]], gates[arg["gate"]])
    raise WorldError(f"unknown condition {kind!r}")


@dataclass
class Scorer:
    """Awards the checkpoints in order, counts falls and decides when the run ends."""

    checkpoints: list[dict[str, Any]]
    gates: dict[str, GateFrame]
    time_limit_s: float
    reached: int = 0
    falls: int = 0
    down: bool = False
    ended: bool = False
    end_reason: str | None = None
    events: list[dict[str, Any]] = field(default_factory=list)

    def update(
        self, sim_time: float, obs: Observation, pelvis_height: float, pelvis_tilt: float
    ) -> list[dict[str, Any]]:
        """Check falls and the next checkpoint (100 Hz); return the new score events."""
        if self.ended:
            return []
        new: list[dict[str, Any]] = []
        is_down = pelvis_height < FALL_HEIGHT or pelvis_tilt > FALL_TILT
        if is_down and not self.down:
            self.falls += 1
            new.append({"event": "fall", "falls": self.falls})
        self.down = is_down
        while self.reached < len(self.checkpoints) and not self.falls >= MAX_FALLS:
            checkpoint = self.checkpoints[self.reached]
            if not evaluate(checkpoint["when"], obs, self.gates):
                break
            self.reached += 1
            new.append(
                {
                    "event": "checkpoint",
                    "checkpoint": self.reached,
                    "name": checkpoint["name"],
                    "points": 1,
                }
            )
        if self.falls >= MAX_FALLS:
            self._end("falls", new)
        elif self.reached == len(self.checkpoints):
            self._end("complete", new)
        elif sim_time >= self.time_limit_s - 1e-9:
            self._end("time_limit", new)
        for event in new:
            event["sim_time"] = round(sim_time, 6)
            event["score"] = self.reached
        self.events.extend(new)
        return new

    def stop(self, sim_time: float, reason: str) -> list[dict[str, Any]]:
        """End the run from outside (the user stopped it)."""
        if self.ended:
            return []
        new: list[dict[str, Any]] = []
        self._end(reason, new)
        for event in new:
            event["sim_time"] = round(sim_time, 6)
            event["score"] = self.reached
        self.events.extend(new)
        return new

    def _end(self, reason: str, new: list[dict[str, Any]]) -> None:
        self.ended, self.end_reason = True, reason
        new.append({"event": "run_end", "reason": reason, "falls": self.falls})
