"""A CloudSim's state worth measuring: a live run with supervision figures, machines, an
unreachable team instance, a waiting upload, a finished and a stuck job."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import timedelta

from cloudsim.extensions import db
from cloudsim.models import (
    Constellation,
    ConstellationState,
    InstanceState,
    Job,
    JobState,
    Machine,
    MachineState,
    PortalUpload,
    Run,
    RunState,
    Task,
    Team,
    TeamInstance,
    utcnow,
)

UPLINK_CAP = 1_000_000
DOWNLINK_CAP = 8_000_000


@dataclass(frozen=True)
class Season:
    """The ids of what `measurable_season` made."""

    team: str
    run_id: int
    constellation_id: int


def measurable_season(
    team_name: str = "Metrics team", *, wall_seconds: float = 100.0, suffix: str = ""
) -> Season:
    """Add a running run that has simulated half its wall time (real-time factor 0.5); names
    and ids end with suffix (several seasons in one database)."""
    now = utcnow()
    team = Team(name=team_name)
    db.session.add(team)
    db.session.flush()
    constellation = Constellation(
        name=f"metrics-vrc{suffix}",
        kind="vrc",
        provider="local",
        team_id=team.id,
        state=ConstellationState.READY,
    )
    db.session.add(constellation)
    db.session.flush()
    for role in ("router", "sim"):
        db.session.add(
            Machine(
                constellation_id=constellation.id,
                name=role,
                role=role,
                state=MachineState.READY,
                created_at=now - timedelta(hours=3),
            )
        )
    task = Task(
        team_id=team.id,
        name="Metrics task",
        world="vrc_task_2",
        window_start=now - timedelta(hours=1),
        window_stop=now + timedelta(hours=1),
        uplink_bits=UPLINK_CAP,
        downlink_bits=DOWNLINK_CAP,
    )
    db.session.add(task)
    db.session.flush()
    run = Run(
        task_id=task.id,
        team_id=team.id,
        constellation_id=constellation.id,
        active_constellation_id=constellation.id,
        state=RunState.RUNNING,
        started_at=now - timedelta(seconds=wall_seconds + 5),
        running_at=now - timedelta(seconds=wall_seconds),
        sim_seconds=wall_seconds / 2,
        uplink_bits_used=250_000,
        downlink_bits_used=2_000_000,
    )
    db.session.add(run)
    db.session.add(
        TeamInstance(
            name=f"team-instance-1{suffix}",
            team_id=team.id,
            constellation_id=constellation.id,
            state=InstanceState.UNREACHABLE,
            last_sync_at=now - timedelta(minutes=10),
        )
    )
    db.session.add(
        Job(
            id=f"job-finished{suffix}",
            kind="diagnostics",
            state=JobState.SUCCEEDED,
            started_at=now - timedelta(seconds=12),
            finished_at=now - timedelta(seconds=2),
        )
    )
    db.session.add(
        Job(
            id=f"job-stuck{suffix}",
            kind="launch",
            state=JobState.QUEUED,
            created_at=now - timedelta(hours=1),
        )
    )
    db.session.flush()
    db.session.add(PortalUpload(run_id=run.id, bytes_total=5000, bytes_sent=1000))
    db.session.commit()
    return Season(team_name, run.id, constellation.id)
