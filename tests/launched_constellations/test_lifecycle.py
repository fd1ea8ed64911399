"""A constellation's state changes only in its lifecycle module."""

from __future__ import annotations

from cloudsim.launched_constellations import lifecycle
from cloudsim.models import Constellation, ConstellationState, Machine, MachineState
from tests.support.sources import state_assignments


def test_only_the_lifecycle_module_sets_constellation_and_machine_states() -> None:
    assert (
        state_assignments(
            ("ConstellationState", "MachineState"), ("launched_constellations/lifecycle.py",)
        )
        == []
    )


def test_terminated_marks_the_constellation_and_every_machine() -> None:
    constellation = Constellation(name="c", kind="simple", provider="local")
    constellation.machines.append(Machine(name="sim", role="sim", size="small"))
    lifecycle.terminating(constellation)
    assert constellation.state == ConstellationState.TERMINATING
    assert [m.state for m in constellation.machines] == [MachineState.TERMINATING]
    lifecycle.terminated(constellation)
    assert constellation.state == ConstellationState.TERMINATED
    assert [m.state for m in constellation.machines] == [MachineState.TERMINATED]
