"""The metrics read from the database and Redis when Prometheus scrapes (a custom collector).

Reading at scrape time, rather than counting in each process, gives every gunicorn worker the
same answer and survives restarts; each query is one grouped SELECT over indexed or small
tables, so a scrape costs a few milliseconds.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from datetime import datetime, timedelta

import redis
from flask import Flask
from prometheus_client.core import GaugeMetricFamily, HistogramMetricFamily, Metric
from prometheus_client.registry import Collector
from sqlalchemy import ColumnElement, Float, case, cast, extract, func, or_, select

from cloudsim.config import Config
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
    UploadState,
    utcnow,
)
from cloudsim.monitoring import heartbeats
from cloudsim.monitoring.health import WAITING, redis_client

QUEUE = "cloudsim"  # the Celery queue (cloudsim.jobs.queue's task_default_queue)
JOB_BUCKETS = (1.0, 5.0, 15.0, 60.0, 300.0, 900.0, 3600.0, 4 * 3600.0)
LIVE_RUNS = (RunState.STARTING, RunState.RUNNING, RunState.STOPPING)


def _seconds(later: datetime, earlier: datetime) -> float:
    return max(0.0, (later - earlier).total_seconds())


def _duration_seconds() -> ColumnElement[float]:
    """Return a job's finished_at - started_at in seconds, in the database's own SQL."""
    if db.engine.dialect.name == "sqlite":
        days = func.julianday(Job.finished_at) - func.julianday(Job.started_at)
        return cast(days * 86400.0, Float)
    return cast(extract("epoch", Job.finished_at - Job.started_at), Float)


class CloudSimCollector(Collector):
    """Yield CloudSim's state as Prometheus metrics, read fresh on every scrape."""

    def __init__(self, app: Flask) -> None:
        self.app = app

    def collect(self) -> Iterator[Metric]:
        with self.app.app_context():
            try:
                yield from self._jobs()
                yield from self._runs()
                yield from self._machines()
                yield from self._instances()
                yield from self._portal()
            finally:
                db.session.rollback()  # read only: end the read transaction
            yield from self._redis(self.app.config["CLOUDSIM"])

    def _jobs(self) -> Iterator[Metric]:
        config: Config = self.app.config["CLOUDSIM"]
        jobs = GaugeMetricFamily(
            "cloudsim_jobs", "Jobs by kind and state", labels=["kind", "state"]
        )
        for kind, state, count in db.session.execute(
            select(Job.kind, Job.state, func.count()).group_by(Job.kind, Job.state)
        ):
            jobs.add_metric([kind, str(state)], count)
        yield jobs
        now = utcnow()
        oldest = db.session.scalar(
            select(func.min(Job.created_at)).where(Job.state == JobState.QUEUED)
        )
        yield GaugeMetricFamily(
            "cloudsim_job_oldest_queued_seconds",
            "Age of the oldest job not yet started (0: none waits)",
            value=_seconds(now, oldest) if oldest else 0.0,
        )
        stale = now - timedelta(seconds=config.stale_job_seconds)
        expired = now - timedelta(seconds=config.job_lease_seconds)
        lost = GaugeMetricFamily(
            "cloudsim_jobs_lost",
            "Jobs past their deadline: queued longer than CLOUDSIM_STALE_JOB_SECONDS, or running"
            " with a lease not renewed for CLOUDSIM_JOB_LEASE_SECONDS",
            labels=["kind"],
        )
        stuck = select(Job.kind, func.count()).where(
            or_(
                (Job.state == JobState.QUEUED) & (Job.created_at < stale),
                (Job.state == JobState.RUNNING) & (Job.heartbeat_at < expired),
            )
        )
        for kind, count in db.session.execute(stuck.group_by(Job.kind)):
            lost.add_metric([kind], count)
        yield lost
        yield self._durations()

    def _durations(self) -> Metric:
        histogram = HistogramMetricFamily(
            "cloudsim_job_duration_seconds",
            "Wall time of finished jobs, from start to end, by kind",
            labels=["kind"],
        )
        # One grouped query counts every bucket in the database: a season's tens of thousands
        # of finished jobs never travel to Python.
        finished = (
            select(Job.kind.label("kind"), _duration_seconds().label("seconds"))
            .where(
                Job.state.in_((JobState.SUCCEEDED, JobState.FAILED)),
                Job.started_at.is_not(None),
                Job.finished_at.is_not(None),
            )
            .subquery()
        )
        seconds = finished.c.seconds  # computed once a row, then compared with each bound
        columns = [func.sum(case((seconds <= bound, 1), else_=0)) for bound in JOB_BUCKETS]
        rows = db.session.execute(
            select(finished.c.kind, func.count(), func.sum(seconds), *columns)
            .group_by(finished.c.kind)
            .order_by(finished.c.kind)
        )
        for kind, count, total, *within in rows:
            buckets = [(str(b), int(n or 0)) for b, n in zip(JOB_BUCKETS, within, strict=True)]
            buckets.append(("+Inf", int(count)))
            histogram.add_metric([kind], buckets, max(0.0, float(total or 0.0)))
        return histogram

    def _runs(self) -> Iterator[Metric]:
        runs = GaugeMetricFamily("cloudsim_runs", "Runs by state", labels=["state"])
        for state, count in db.session.execute(select(Run.state, func.count()).group_by(Run.state)):
            runs.add_metric([str(state)], count)
        yield runs
        labels = ["run_id", "team"]
        rtf = GaugeMetricFamily(
            "cloudsim_run_real_time_factor",
            "A running run's simulated seconds per wall second since it began running",
            labels=labels,
        )
        sim = GaugeMetricFamily(
            "cloudsim_run_sim_seconds", "A live run's simulated time so far", labels=labels
        )
        used = GaugeMetricFamily(
            "cloudsim_run_bits_used",
            "A live run's bits used so far, by direction",
            labels=[*labels, "direction"],
        )
        left = GaugeMetricFamily(
            "cloudsim_run_bits_left",
            "A live run's bits left of its task's cap, by direction",
            labels=[*labels, "direction"],
        )
        now = utcnow()
        live = db.session.execute(
            select(Run, Task.uplink_bits, Task.downlink_bits, Team.name)
            .join(Task, Run.task_id == Task.id)
            .join(Team, Run.team_id == Team.id)
            .where(Run.state.in_(LIVE_RUNS))
        )
        for run, uplink_cap, downlink_cap, team in live:
            names = [str(run.id), team]
            sim.add_metric(names, run.sim_seconds)
            if run.state == RunState.RUNNING and run.running_at is not None:
                wall = _seconds(now, run.running_at)
                if wall > 0:
                    rtf.add_metric(names, run.sim_seconds / wall)
            for direction, spent, cap in (
                ("uplink", run.uplink_bits_used, uplink_cap),
                ("downlink", run.downlink_bits_used, downlink_cap),
            ):
                used.add_metric([*names, direction], spent)
                left.add_metric([*names, direction], max(0, cap - spent))
        yield from (rtf, sim, used, left)

    def _machines(self) -> Iterator[Metric]:
        constellations = GaugeMetricFamily(
            "cloudsim_constellations",
            "Constellations by state, provider and kind",
            labels=["state", "provider", "kind"],
        )
        for state, provider, kind, count in db.session.execute(
            select(
                Constellation.state, Constellation.provider, Constellation.kind, func.count()
            ).group_by(Constellation.state, Constellation.provider, Constellation.kind)
        ):
            constellations.add_metric([str(state), provider, kind], count)
        yield constellations
        machines = GaugeMetricFamily(
            "cloudsim_machines", "Machines by state and provider", labels=["state", "provider"]
        )
        for machine_state, provider, count in db.session.execute(
            select(Machine.state, Constellation.provider, func.count())
            .join(Constellation, Machine.constellation_id == Constellation.id)
            .group_by(Machine.state, Constellation.provider)
        ):
            machines.add_metric([str(machine_state), provider], count)
        yield machines
        hours = GaugeMetricFamily(
            "cloudsim_team_machine_hours",
            "Hours the team's machines that exist now have existed (the machine-hours they cost"
            " so far)",
            labels=["team"],
        )
        now = utcnow()
        totals: dict[str, float] = {}
        for created, team in db.session.execute(
            select(Machine.created_at, Team.name)
            .join(Constellation, Machine.constellation_id == Constellation.id)
            .join(Team, Constellation.team_id == Team.id)
            .where(Machine.state != MachineState.TERMINATED)
            .where(Constellation.state != ConstellationState.TERMINATED)
        ):
            totals[team] = totals.get(team, 0.0) + _seconds(now, created) / 3600
        for team, total in sorted(totals.items()):
            hours.add_metric([team], total)
        yield hours

    def _instances(self) -> Iterator[Metric]:
        labels = ["team_instance", "team"]
        up = GaugeMetricFamily(
            "cloudsim_team_instance_up",
            "1 when the master's last health check reached the team instance, else 0",
            labels=labels,
        )
        lag = GaugeMetricFamily(
            "cloudsim_team_instance_sync_lag_seconds",
            "Seconds since the master last brought the team instance up to date",
            labels=labels,
        )
        now = utcnow()
        for instance, team in db.session.execute(
            select(TeamInstance, Team.name)
            .outerjoin(Team, TeamInstance.team_id == Team.id)
            .where(TeamInstance.state.in_((InstanceState.READY, InstanceState.UNREACHABLE)))
        ):
            names = [instance.name, team or ""]
            up.add_metric(names, 1.0 if instance.state == InstanceState.READY else 0.0)
            since = instance.last_sync_at or instance.created_at
            lag.add_metric(names, _seconds(now, since))
        yield from (up, lag)

    def _portal(self) -> Iterator[Metric]:
        uploads = GaugeMetricFamily(
            "cloudsim_portal_uploads",
            "On a team instance: finished runs in the outbox to the master, by state",
            labels=["state"],
        )
        counts = dict.fromkeys(UploadState, 0)
        for state, count in db.session.execute(
            select(PortalUpload.state, func.count()).group_by(PortalUpload.state)
        ):
            counts[state] = count
        for state, count in counts.items():
            uploads.add_metric([str(state)], count)
        yield uploads
        backlog, oldest = db.session.execute(
            select(
                func.coalesce(func.sum(PortalUpload.bytes_total - PortalUpload.bytes_sent), 0),
                func.min(PortalUpload.created_at),
            ).where(PortalUpload.state.in_(WAITING))
        ).one()
        yield GaugeMetricFamily(
            "cloudsim_portal_upload_backlog_bytes",
            "On a team instance: log bytes still to send to the master",
            value=float(backlog),
        )
        yield GaugeMetricFamily(
            "cloudsim_portal_upload_oldest_seconds",
            "On a team instance: how long the oldest run waiting to upload has waited",
            value=_seconds(utcnow(), oldest) if oldest else 0.0,
        )

    def _redis(self, config: Config) -> Iterator[Metric]:
        try:
            client = redis_client(config)
            depth = client.llen(QUEUE)
            seen = heartbeats.heard(client)
        except redis.RedisError:
            yield GaugeMetricFamily("cloudsim_redis_up", "1 when Redis answered", value=0.0)
            return
        yield GaugeMetricFamily("cloudsim_redis_up", "1 when Redis answered", value=1.0)
        yield GaugeMetricFamily(
            "cloudsim_queue_messages", "Job messages waiting in the queue", value=float(depth)
        )
        workers = GaugeMetricFamily(
            "cloudsim_worker_heartbeat_timestamp_seconds",
            "When each worker last ran a task (UNIX time)",
            labels=["worker"],
        )
        for who, at in sorted(seen.items()):
            if who.startswith(heartbeats.WORKER):
                workers.add_metric([who.removeprefix(heartbeats.WORKER)], at)
        yield workers
        if heartbeats.BEAT in seen:
            yield GaugeMetricFamily(
                "cloudsim_beat_heartbeat_timestamp_seconds",
                "When the beat last sent a task (UNIX time)",
                value=seen[heartbeats.BEAT],
            )
        yield GaugeMetricFamily(
            "cloudsim_scrape_timestamp_seconds", "When this answer was made", value=time.time()
        )
