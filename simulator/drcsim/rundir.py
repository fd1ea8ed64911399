"""A run directory's contract: its file names, how to start a served run, and the readers.

This module is what an orchestrator imports (CloudSim does) instead of re-declaring the
simulator's formats: it needs only the standard library, so importing it pulls in neither
pybullet nor ZeroMQ.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

META = "meta.json"
COMMANDS = "commands.jsonl"
STATE = "state.msgpack"
SCORE = "score.jsonl"
FINAL = "final.json"
# The world document the run was built from, when the orchestrator handed one over.
WORLD = "world.json"
# The run's log for robotics tools (MCAP, JSON messages; drcsim.mcaplog writes it).
MCAP = "run.mcap"
# The router's bandwidth as MCAP, made by CloudSim when it collects a run (open it with MCAP).
BANDWIDTH_MCAP = "bandwidth.mcap"
# The served run's live figures (simulated time, RTF, score), rewritten about twice a second
# while it runs; not a log (it is not collected): a supervisor reads it to follow the run live.
LIVE = "live.json"
LIVE_EVERY_S = 0.5
# Every file a finished run leaves in its directory; FINAL is missing if the simulator died.
FILES = (SCORE, STATE, COMMANDS, META, FINAL, MCAP)
# The score log's events worth keeping (run_start says nothing).
SCORE_EVENTS = ("checkpoint", "fall", "run_end")


class ScoreLogError(ValueError):
    """A score log line is not what the simulator writes."""


@dataclass(frozen=True)
class ScoreEvent:
    """One line of the score log."""

    kind: str
    sim_time: float
    wall_time: datetime
    checkpoint: int | None = None
    points: int = 0
    description: str = ""


@dataclass
class RunScore:
    """What a score log says: its events, the score, falls, simulated time and how it ended."""

    events: list[ScoreEvent] = field(default_factory=list)
    score: int = 0
    falls: int = 0
    end_reason: str | None = None
    sim_seconds: float = 0.0


def serve_argv(
    drcsim: str,
    world: str,
    config: int | str,
    *,
    bind: str,
    allow: Sequence[str],
    log_dir: str,
    time_limit_s: float,
    world_file: str | None = None,
) -> list[str]:
    """Return the argv of `drcsim serve` for one run writing its logs to log_dir (building
    the world from `world_file` instead of the shipped copy, if given)."""
    return [
        drcsim,
        "serve",
        "--world",
        world,
        "--config",
        str(config),
        "--bind",
        bind,
        *[part for network in allow for part in ("--allow", network)],
        "--log-dir",
        log_dir,
        "--time-limit",
        str(time_limit_s),
        *(["--world-file", world_file] if world_file else []),
    ]


def read_meta(directory: Path) -> dict[str, Any]:
    """Return a run's metadata."""
    data: dict[str, Any] = json.loads((directory / META).read_text())
    return data


def read_final(directory: Path) -> dict[str, Any]:
    """Return a run's final record."""
    data: dict[str, Any] = json.loads((directory / FINAL).read_text())
    return data


def write_live(directory: Path, figures: dict[str, Any]) -> None:
    """Replace the run's live figures at once (a reader never sees half a file)."""
    partial = directory / f".{LIVE}.tmp"
    partial.write_text(json.dumps(figures, sort_keys=True))
    os.replace(partial, directory / LIVE)


def read_live(text: str) -> dict[str, Any] | None:
    """Return the live figures from LIVE's text; None when there are none (yet) or unreadable."""
    try:
        data = json.loads(text)
    except ValueError:
        return None
    return data if isinstance(data, dict) and "sim_time" in data else None


def read_score_log(lines: Iterable[str]) -> RunScore:
    """Return the score from a score log's lines, so far if the run goes on.

    A torn last line (the simulator killed mid-write, or a copy taken while it writes) is
    ignored; a bad line before it is an error.
    """
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
        if event.kind in SCORE_EVENTS:
            result.events.append(event)
    return result


def _event(data: dict[str, Any]) -> ScoreEvent:
    kind = str(data["event"])
    description = str(data.get("name") or data.get("reason") or "")
    if kind == "fall":
        description = f"fall {data.get('falls', '')}".strip()
    return ScoreEvent(
        kind=kind,
        sim_time=float(data["sim_time"]),
        wall_time=datetime.fromtimestamp(float(data["wall_time"]), tz=UTC),
        checkpoint=int(data["checkpoint"]) if data.get("checkpoint") is not None else None,
        points=int(data.get("points", 0)),
        description=description[:255],
    )


def read_run_span(lines: Iterable[str]) -> tuple[float | None, float | None]:
    """Return when (epoch seconds) the score log says the run started and ended, None for
    what it does not say (a torn or foreign line is skipped)."""
    started = ended = None
    for line in lines:
        try:
            data = json.loads(line)
            if isinstance(data, dict) and data.get("event") == "run_start":
                started = float(data["wall_time"])
            elif isinstance(data, dict) and data.get("event") == "run_end":
                ended = float(data["wall_time"])
        except (ValueError, KeyError, TypeError):
            continue
    return started, ended
