"""Scoring from data: ordered checkpoints as conditions over observations, falls, run end.

Two conditions carry memory so that they cannot be gamed: `through_gate` holds once the body
has crossed the gate line between the posts in the gate's direction (stepping into the zone
past the line from the side does not count; crossing back undoes it), and `increase` measures
a quantity's change since the previous checkpoint was awarded (turning the valve before the
hose is connected earns nothing).

A fallen robot earns nothing: no checkpoint is awarded while it is down or in its first
STEADY_S seconds up again, a crossing made then is ignored, and a crossing counts only once
the robot has stayed up for STEADY_S after it (a dive through a gate line is a fall).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from drcsim.errors import WorldError

FALL_HEIGHT = 0.6  # pelvis above the ground, metres
FALL_TILT = math.radians(45)
MAX_FALLS = 3
# Seconds the robot must be up before and after a crossing, and up before any award: longer
# than a topple takes from upright to down (about 1 s) and than the walker's stop.
STEADY_S = 3.0


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


@dataclass
class Memory:
    """What conditions remember between ticks: gates crossed, quantities at the last award."""

    crossed: set[tuple[str, str]] = field(default_factory=set)
    baseline: dict[str, float] = field(default_factory=dict)
    # crossings made while the robot was steady, by the time they were made: each becomes a
    # crossing when the robot has stayed up STEADY_S after it; a fall forgets them
    pending: dict[tuple[str, str], float] = field(default_factory=dict)


def _gate_coordinates(position: tuple[float, ...], gate: GateFrame) -> tuple[float, float]:
    dx, dy = position[0] - gate.x, position[1] - gate.y
    c, s = math.cos(gate.yaw), math.sin(gate.yaw)
    return c * dx + s * dy, -s * dx + c * dy


def crossing(before: tuple[float, ...], after: tuple[float, ...], gate: GateFrame) -> int:
    """Return +1 (crossed forwards between the posts), -1 (backwards) or 0 (no crossing)."""
    along0, across0 = _gate_coordinates(before, gate)
    along1, across1 = _gate_coordinates(after, gate)
    if (along0 < 0.0) == (along1 < 0.0):
        return 0
    # Where the straight path from one tick to the next meets the gate line.
    across = across0 + (across1 - across0) * (-along0) / (along1 - along0)
    if abs(across) > gate.width / 2:
        return 0
    return 1 if along1 >= 0.0 else -1


def evaluate(
    condition: dict[str, Any],
    obs: Observation,
    gates: dict[str, GateFrame],
    memory: Memory | None = None,
) -> bool:
    """Return whether `condition` (a one-key mapping, see README) holds for `obs`."""
    memory = memory or Memory()
    if len(condition) != 1:
        raise WorldError(f"a condition has exactly one key, not {sorted(condition)}")
    ((kind, arg),) = condition.items()
    if kind == "all":
        return all(evaluate(part, obs, gates, memory) for part in arg)
    if kind == "any":
        return any(evaluate(part, obs, gates, memory) for part in arg)
    if kind == "flag":
        return bool(obs.flags.get(arg, False))
    if kind == "not_flag":
        return not obs.flags.get(arg, False)
    if kind == "at_least":
        return obs.quantities.get(arg["quantity"], -math.inf) >= float(arg["value"])
    if kind == "at_most":
        return obs.quantities.get(arg["quantity"], math.inf) <= float(arg["value"])
    if kind == "increase":
        now = obs.quantities.get(arg["quantity"], -math.inf)
        return now - memory.baseline.get(arg["quantity"], now) >= float(arg["value"])
    if kind == "through_gate":
        if arg["gate"] not in gates or arg["body"] not in obs.positions:
            raise WorldError(f"through_gate names unknown gate or body: {arg}")
        return (arg["body"], arg["gate"]) in memory.crossed
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
    memory: Memory = field(default_factory=Memory)
    previous: Observation | None = None
    up_since: float | None = 0.0  # the run starts with the robot standing

    def steady(self, sim_time: float) -> bool:
        """Return whether the robot has been up for STEADY_S (what earns anything)."""
        return self.up_since is not None and sim_time - self.up_since >= STEADY_S - 1e-9

    def _remember(self, obs: Observation, sim_time: float) -> None:
        before, memory = self.previous, self.memory
        if before is None:
            memory.baseline = dict(obs.quantities)
        else:
            for body, position in obs.positions.items():
                if body not in before.positions:
                    continue
                for name, gate in self.gates.items():
                    direction = crossing(before.positions[body], position, gate)
                    if direction > 0 and self.steady(sim_time):
                        memory.pending[(body, name)] = sim_time
                    elif direction < 0:
                        memory.crossed.discard((body, name))
                        memory.pending.pop((body, name), None)
        for key, when in list(memory.pending.items()):
            if sim_time - when >= STEADY_S - 1e-9:
                memory.crossed.add(key)
                del memory.pending[key]
        self.previous = obs

    def _track_falls(self, sim_time: float, is_down: bool, new: list[dict[str, Any]]) -> None:
        if is_down and not self.down:
            self.falls += 1
            new.append({"event": "fall", "falls": self.falls})
            self.memory.pending.clear()  # what it crossed falling is not a crossing
        if is_down:
            self.up_since = None
        elif self.up_since is None:
            self.up_since = sim_time
        self.down = is_down

    def update(
        self, sim_time: float, obs: Observation, pelvis_height: float, pelvis_tilt: float
    ) -> list[dict[str, Any]]:
        """Check falls and the next checkpoint (100 Hz); return the new score events."""
        if self.ended:
            return []
        new: list[dict[str, Any]] = []
        self._track_falls(sim_time, pelvis_height < FALL_HEIGHT or pelvis_tilt > FALL_TILT, new)
        self._remember(obs, sim_time)
        steady = self.steady(sim_time)
        while steady and self.reached < len(self.checkpoints) and not self.falls >= MAX_FALLS:
            checkpoint = self.checkpoints[self.reached]
            if not evaluate(checkpoint["when"], obs, self.gates, self.memory):
                break
            self.reached += 1
            self.memory.baseline = dict(obs.quantities)
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
