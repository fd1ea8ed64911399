"""A run's state changes only in its lifecycle module."""

from __future__ import annotations

from cloudsim.competition import lifecycle
from cloudsim.models import RunState
from tests.support.sources import state_assignments


def test_only_the_lifecycle_module_sets_run_states() -> None:
    assert state_assignments(("RunState",), ("competition/lifecycle.py",)) == []


def test_a_new_run_is_starting_and_an_ended_run_frees_its_constellation() -> None:
    run = lifecycle.new_run(task_id=1, team_id=1, constellation_id=7, active_constellation_id=7)
    assert run.state == RunState.STARTING
    lifecycle.ended(run, "sim: broken", failed=True)
    assert (run.state, run.error, run.active_constellation_id) == (
        RunState.ERROR,
        "sim: broken",
        None,
    )
    assert run.finished_at is not None
