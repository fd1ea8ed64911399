"""The VRC ranking of teams from their runs' results (pure functions).

A run's score comes from its score log, read by drcsim's own reader (drcsim.rundir).

Ranking: most checkpoints first; ties broken by the largest share of uplink bits left over
all the team's runs, then by the most seconds left (summed over runs that reached every
checkpoint: time left is only worth something once the task is done), then by name.
Runs an officer invalidated, and runs held for review by verification, are not given to the
ranking at all; a standing only counts them (and the ranked runs not verified yet).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass


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
    invalidated: int = 0  # the team's finished runs an officer invalidated (not counted)
    unverified: int = 0  # of its ranked runs, those whose replay has not verified them yet
    held: int = 0  # the team's finished runs held for review (not counted until accepted)


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


def rank(
    teams: dict[tuple[int, str], list[RunResult]],
    invalidated: dict[int, int] | None = None,
    *,
    unverified: dict[int, int] | None = None,
    held: dict[int, int] | None = None,
) -> list[Standing]:
    """Order teams by the VRC rules; equal figures share a rank. `invalidated` and `held` count
    each team's runs left out, `unverified` its ranked runs not verified yet (shown beside its
    standing)."""
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
                invalidated=(invalidated or {}).get(team_id, 0),
                unverified=(unverified or {}).get(team_id, 0),
                held=(held or {}).get(team_id, 0),
            )
        )
    return standings
