"""A constellation's life: the kind is kept as launched, and a terminated name can be reused."""

from __future__ import annotations

import pytest
from flask import Flask
from sqlalchemy import func, select

from cloudsim.auth.policy import SYSTEM
from cloudsim.errors import Conflict
from cloudsim.extensions import db
from cloudsim.launched_constellations import service
from cloudsim.models import Constellation, ConstellationState
from constellations.definition import load_kind


def test_a_terminated_name_can_be_launched_again_and_its_history_stays(app: Flask) -> None:
    first, _ = service.launch(SYSTEM, name="again", kind="simple", provider="local")
    with pytest.raises(Conflict):
        service.launch(SYSTEM, name="again", kind="simple", provider="local")
    first.state = ConstellationState.TERMINATED
    db.session.commit()

    second, _ = service.launch(SYSTEM, name="again", kind="simple", provider="local")
    db.session.commit()
    assert second.id != first.id
    count = select(func.count()).where(Constellation.name == "again")
    assert db.session.scalar(count) == 2  # the terminated one is kept
    assert service.get_constellation(SYSTEM, "again").id == second.id  # the live one


def test_the_kind_is_stored_at_launch_and_jobs_use_it(app: Flask) -> None:
    constellation, _ = service.launch(SYSTEM, name="kept", kind="vrc", provider="local")
    db.session.commit()
    assert constellation.definition is not None and constellation.definition["name"] == "vrc"
    assert service.launched_kind(constellation) == load_kind("vrc")
    # what the constellation was launched as holds even if the kind's file changes later
    constellation.definition = {**constellation.definition, "description": "as launched"}
    assert service.launched_kind(constellation).description == "as launched"
