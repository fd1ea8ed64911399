"""Scores from the simulator's score log, and the VRC ranking of teams (pure functions).

Ranking: most checkpoints first; ties broken by the largest share of uplink bits left over
all the team's runs, then by the most seconds left (summed over runs that reached every
checkpoint: time left is only worth something once the task is done), then by name.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

# The simulator's events a run keeps in the database (run_start says nothing).
KEPT_EVENTS = ("checkpoint", "fall", "run_end")


class ScoreLogError(ValueError):
    """A score log line is not what the simulator writes."""


@dataclass(frozen=True)
class Event:
    """One line of the score log."""

    kind: str
    sim_time: float
    wall_time: datetime
    checkpoint: int | None = None
    points: int = 0
    description: str = ""


@dataclass
class RunScore:
    """What a run's score log says: its events, checkpoints, falls and how it ended."""

    events: list[Event] = field(default_factory=list)
    score: int = 0
    falls: int = 0
    end_reason: str | None = None
    sim_seconds: float = 0.0


def read_score_log(lines: Iterable[str]) -> RunScore:
    """Return the score of a run from its score.jsonl lines (a partial log gives the score so
    far; a torn last line, as when the simulator was killed mid-write, is ignored)."""
    result = RunScore()
    buffered = list(lines)
    for number, line in enumerate(buffered, start=1):
        if not line.strip():
            continue
        try:
            data = json.loads(line)
            if not isinstance(data, dict):
                raise ValueError("not an object")
            event = _event(data)
        except (ValueError, KeyError, TypeError) as exc:
            if number == len(buffered):
                break
            raise ScoreLogError(f"score log line {number}: {exc}") from None
        result.sim_seconds = max(result.sim_seconds, event.sim_time)
        result.score = max(result.score, int(data.get("score", result.score)))
        if event.kind == "fall":
            result.falls = max(result.falls, int(data.get("falls", result.falls + 1)))
        if event.kind == "run_end":
            result.end_reason = str(data.get("reason") or "ended")
            result.falls = int(data.get("falls", result.falls))
        if event.kind in KEPT_EVENTS:
            result.events.append(event)
    return result


def _event(data: dict[str, Any]) -> Event:
    kind = str(data["event"])
    description = str(data.get("name") or data.get("reason") or "")
    if kind == "fall":
        description = f"fall {data.get('falls', '')}".strip()
    return Event(
        kind=kind,
        sim_time=float(data["sim_time"]),
        wall_time=datetime.fromtimestamp(float(data["wall_time"]), tz=UTC),
        checkpoint=int(data["checkpoint"]) if data.get("checkpoint") is not None else None,
        points=int(data.get("points", 0)),
        description=description[:255],
    )


@dataclass(frozen=True)
class RunResult:
    """One finished run as the ranking sees it."""

    checkpoints: int
    uplink_cap_bits: int
    uplink_used_bits: int
    timeout_s: int
    sim_seconds: float
    complete: bool

    @property
    def seconds_left(self) -> float:
        """Return the simulated seconds left when the task was done (0 when it was not)."""
        return max(0.0, self.timeout_s - self.sim_seconds) if self.complete else 0.0


@dataclass(frozen=True)
class Standing:
    """A team's place on the leaderboard and the figures behind it."""

    rank: int
    team_id: int
    team: str
    runs: int
    checkpoints: int
    uplink_share_left: float
    seconds_left: float


def standing_figures(results: Iterable[RunResult]) -> tuple[int, int, float, float]:
    """Return (runs, checkpoints, share of uplink bits left over all runs, seconds left)."""
    results = list(results)
    cap = sum(r.uplink_cap_bits for r in results)
    left = sum(max(0, r.uplink_cap_bits - r.uplink_used_bits) for r in results)
    share = left / cap if cap else 0.0
    return (
        len(results),
        sum(r.checkpoints for r in results),
        share,
        sum(r.seconds_left for r in results),
    )


def rank(teams: dict[tuple[int, str], list[RunResult]]) -> list[Standing]:
    """Order teams by the VRC rules; equal figures share a rank."""
    rows = []
    for (team_id, name), results in teams.items():
        runs, checkpoints, share, seconds = standing_figures(results)
        rows.append((team_id, name, runs, checkpoints, round(share, 9), round(seconds, 3)))
    rows.sort(key=lambda r: (-r[3], -r[4], -r[5], r[1].lower(), r[0]))
    standings: list[Standing] = []
    for index, (team_id, name, runs, checkpoints, share, seconds) in enumerate(rows):
        previous = standings[-1] if standings else None
        tied = previous is not None and (
            previous.checkpoints,
            previous.uplink_share_left,
            previous.seconds_left,
        ) == (checkpoints, share, seconds)
        standings.append(
            Standing(
                rank=previous.rank if tied and previous else index + 1,
                team_id=team_id,
                team=name,
                runs=runs,
                checkpoints=checkpoints,
                uplink_share_left=share,
                seconds_left=seconds,
            )
        )
    return standings
