"""What a replay reproduced against what the run claims (pure functions).

The run's figures (score, falls, simulated time, how it ended, its checkpoint and fall events)
and its score log are each compared with the replay's; every difference is named.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from drcsim.rundir import RunScore

TIME_TOLERANCE_S = 1.5e-3  # a score event's time is rounded to 1 µs, a step is 1 ms
# Ends the simulator decides itself; any other end (stopped, window, closed) comes from outside.
SELF_ENDS = ("complete", "falls", "time_limit")


@dataclass(frozen=True)
class Claim:
    """What a run (its record, or its score log) says happened."""

    source: str  # "the run" or "the score log"
    score: int
    falls: int
    sim_seconds: float
    end_reason: str | None
    events: tuple[tuple[str, float], ...]  # ("checkpoint 2" / "fall", simulated time)


def event_key(kind: str, checkpoint: int | None) -> str:
    """Return how an event is named in comparisons."""
    return f"checkpoint {checkpoint}" if kind == "checkpoint" else kind


def claimed_events(events: Iterable[Any]) -> tuple[tuple[str, float], ...]:
    """Return the checkpoint and fall events of score events (rows or drcsim's), in order."""
    return tuple(
        (event_key(e.kind, e.checkpoint), float(e.sim_time))
        for e in events
        if e.kind in ("checkpoint", "fall")
    )


def score_log_claim(log: RunScore) -> Claim:
    """Return what a score log claims."""
    return Claim(
        "the score log",
        log.score,
        log.falls,
        log.sim_seconds,
        log.end_reason,
        claimed_events(log.events),
    )


def replayed_events(result: dict[str, Any]) -> tuple[tuple[str, float], ...]:
    """Return the replay's checkpoint and fall events as claims name them."""
    return tuple(
        (event_key(e["event"], e.get("checkpoint")), float(e["sim_time"]))
        for e in result.get("events", ())
    )


def differences(claim: Claim, result: dict[str, Any]) -> list[str]:
    """Return each way the claim differs from the replay's result (empty: it matches)."""
    found: list[str] = []
    who = claim.source
    if claim.score != result["score"]:
        found.append(
            f"{who} claims {claim.score} checkpoint(s), the replay reaches {result['score']}"
        )
    if claim.falls != result["falls"]:
        found.append(f"{who} claims {claim.falls} fall(s), the replay has {result['falls']}")
    if abs(claim.sim_seconds - result["sim_seconds"]) > TIME_TOLERANCE_S:
        found.append(
            f"{who} lasts {claim.sim_seconds:g} simulated seconds, the replay "
            f"{result['sim_seconds']:g}"
        )
    replayed = replayed_events(result)
    if len(claim.events) != len(replayed) or any(
        name != again or abs(t - t_again) > TIME_TOLERANCE_S
        for (name, t), (again, t_again) in zip(claim.events, replayed, strict=False)
    ):
        found.append(f"{who} has events {_shown(claim.events)}, the replay {_shown(replayed)}")
    ended = result.get("end_reason")
    if ended in SELF_ENDS and claim.end_reason != ended:
        found.append(f"{who} ended {claim.end_reason}, the replay ended {ended}")
    if ended not in SELF_ENDS and claim.end_reason in SELF_ENDS:
        found.append(f"{who} ended {claim.end_reason}, the replay did not end so")
    return found


def _shown(events: tuple[tuple[str, float], ...]) -> str:
    return "[" + ", ".join(f"{name} at {t:g} s" for name, t in events) + "]" if events else "none"
