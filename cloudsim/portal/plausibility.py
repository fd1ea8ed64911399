"""On the master: the figures of an uploaded run that cannot be right, refused before anything
is stored (400 with the reason).

These are checks of the record against itself, its task and its world: they need no log. What
the logs prove (the score reached again by re-simulation) is `cloudsim.verification`'s.
"""

from __future__ import annotations

from datetime import datetime, timedelta
from typing import Any

from drcsim.rundir import COMMANDS, META, SCORE, STATE
from drcsim.scoring import MAX_FALLS

from cloudsim.models import RunState, Task
from cloudsim.portal.ingest import Refused
from cloudsim.worlds.service import check_world

# The logs without which a finished run cannot be re-simulated: declared, or refused. (The
# final record may be missing when the simulator died: verification then holds the run.)
PROOF_LOGS = (SCORE, COMMANDS, META, STATE)
SIM_TIME_SLACK_S = 1e-3  # score log times are rounded to the microsecond; steps are 1 ms
# The simulator paces a served run to the wall clock (never ahead of it) from a moment after
# the run's start is recorded; what the two clocks' granularity allows on top:
WALL_SLACK_S = 2.0
WALL_SLACK_SHARE = 0.01
# score events carry the sim machine's clock, the run's times this CloudSim's: NTP keeps them
# within far less, and the check is about events placed outside the run, not about skew
EVENT_WALL_SLACK = timedelta(seconds=60)


class Implausible(Refused):
    """A run whose own figures contradict each other, its task or its world."""

    status = 400


def check_figures(task: Task, record_: dict[str, Any]) -> None:
    """Refuse a run record whose figures cannot be right (raise Implausible with the reason)."""
    checkpoints = len(check_world(task.world, task.run_config).checkpoints)
    _check_totals(task, record_, checkpoints)
    _check_events(record_, checkpoints)
    _check_clock(record_)
    if record_["state"] == RunState.FINISHED.value:
        declared = {log["filename"] for log in record_["logs"]}
        missing = [name for name in PROOF_LOGS if name not in declared]
        if missing:
            raise Implausible(
                f"a finished run must declare the logs it is re-simulated from; missing: "
                f"{', '.join(missing)}"
            )


def _check_totals(task: Task, record_: dict[str, Any], checkpoints: int) -> None:
    score, falls, sim_seconds = record_["score"], record_["falls"], record_["sim_seconds"]
    if score > checkpoints:
        raise Implausible(f"score {score} on a world of {checkpoints} checkpoints")
    if sim_seconds > task.timeout_s + SIM_TIME_SLACK_S:
        raise Implausible(
            f"{sim_seconds:g} simulated seconds against the task's timeout of {task.timeout_s} s"
        )
    if falls > MAX_FALLS:
        raise Implausible(f"{falls} falls: {MAX_FALLS} falls end a run")
    if record_["end_reason"] == "complete" and score != checkpoints:
        raise Implausible(f"ended complete with {score} of the world's {checkpoints} checkpoints")
    if record_["end_reason"] == "falls" and falls != MAX_FALLS:
        raise Implausible(f"ended by falls after {falls} of them ({MAX_FALLS} end a run)")


def _check_events(record_: dict[str, Any], checkpoints: int) -> None:
    events: list[dict[str, Any]] = record_["score_events"]
    reached = [e for e in events if e["kind"] == "checkpoint"]
    for number, event in enumerate(reached, start=1):
        named = event["checkpoint"]
        if named is None or not 1 <= named <= checkpoints:
            raise Implausible(
                f"a score event names checkpoint {named}: the world has checkpoints 1 to "
                f"{checkpoints}"
            )
        if named != number:
            raise Implausible(
                f"score events out of order: checkpoint {named} is the {number}. reached "
                "(checkpoints are reached in order, each once)"
            )
    points = sum(e["points"] for e in events)
    if points != record_["score"] or len(reached) != record_["score"]:
        raise Implausible(
            f"the score events add up to {points} point(s) over {len(reached)} checkpoint(s); "
            f"the run claims a score of {record_['score']}"
        )
    falls = sum(1 for e in events if e["kind"] == "fall")
    if falls > record_["falls"]:
        raise Implausible(f"{falls} fall events, but the run claims {record_['falls']} falls")
    times = [e["sim_time"] for e in events]
    for index in range(1, len(times)):
        if times[index] < times[index - 1]:
            raise Implausible(
                f"score events out of order: event {index + 1} at {times[index]:g} s comes "
                f"after one at {times[index - 1]:g} s"
            )
    if times and times[-1] > record_["sim_seconds"] + SIM_TIME_SLACK_S:
        raise Implausible(
            f"a score event at {times[-1]:g} s, after the run's {record_['sim_seconds']:g} "
            "simulated seconds"
        )
    started: datetime = record_["started_at"]
    finished: datetime | None = record_["finished_at"]
    for event in events:
        when: datetime = event["wall_time"]
        if when < started - EVENT_WALL_SLACK or (
            finished is not None and when > finished + EVENT_WALL_SLACK
        ):
            raise Implausible(
                f"a score event at {when:%Y-%m-%d %H:%M:%S} UTC, outside the run "
                f"({started:%H:%M:%S} to {finished:%H:%M:%S} UTC)"
                if finished is not None
                else f"a score event at {when:%Y-%m-%d %H:%M:%S} UTC, before the run started"
            )


def _check_clock(record_: dict[str, Any]) -> None:
    started: datetime = record_["started_at"]
    finished: datetime | None = record_["finished_at"]
    if finished is None:
        return  # refused as not ended by the window check
    span = (finished - started).total_seconds()
    most = span * (1 + WALL_SLACK_SHARE) + WALL_SLACK_S
    if record_["sim_seconds"] > most:
        raise Implausible(
            f"{record_['sim_seconds']:g} simulated seconds in a run that lasted {span:g} "
            "seconds of wall-clock time (the simulator never runs ahead of real time)"
        )
