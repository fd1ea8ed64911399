"""Where a launch, retry or terminate is: its step, since when, and when each machine was
last heard from, one answer for the constellation page and the API."""

from __future__ import annotations

from typing import Any

from flask import current_app

from cloudsim.api.common import columns
from cloudsim.jobs.progress import job_step
from cloudsim.launched_constellations import service
from cloudsim.models import Constellation


def last_heard(constellation: Constellation) -> dict[str, str]:
    """Return when CloudSim last heard from each machine: a live run's reader, or verification."""
    from cloudsim.competition.live import machines_heard  # the live reader is the runs' feature

    heard = machines_heard(current_app.config["CLOUDSIM"], constellation.id)
    for machine in constellation.machines:
        verified = (machine.verification or {}).get("at")
        if verified and machine.name not in heard:
            heard[machine.name] = f"{verified} (verification)"
    return heard


def detail(constellation: Constellation) -> dict[str, Any]:
    """Return a constellation's columns, its latest job's step and since when, and its
    machines, each with when it was last heard from."""
    heard = last_heard(constellation)
    return {
        **columns(constellation),
        **job_step(service.latest_job(constellation)),
        "machines": [{**columns(m), "heard": heard.get(m.name)} for m in constellation.machines],
    }
