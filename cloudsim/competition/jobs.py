"""A run's life as jobs: start (arm the router, start the simulator) and stop (stop it,
disarm, collect the logs, score).

Both are resumable step by step: each step reads a fact from the machines before it acts
(`run_steps.py`), so the router is armed before the simulator starts and only once per run,
and the run's bandwidth log is cut to the simulator's own span (docs/metering.md).

The simulator runs on `sim` as a transient systemd service, so it outlives the job (and the
worker) that started it; the beat (`supervision.py`) decides when it ends, whoever started it.
"""

from __future__ import annotations

import json
import shlex
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import datetime

from csrouter.bandwidth_log import read_bandwidth_log
from drcsim.rundir import BANDWIDTH_MCAP, FINAL, SCORE, WORLD, read_score_log, serve_argv
from flask import current_app
from mcap.exceptions import McapError
from sqlalchemy import select

from cloudsim.competition import current_run, lifecycle
from cloudsim.competition.artifacts import LogStore, artifact_for, collect_logs, run_dir
from cloudsim.competition.lifecycle import RunJob
from cloudsim.competition.login_logs import snapshot_login_logs
from cloudsim.competition.run_mcap import store_bandwidth_mcap
from cloudsim.competition.run_steps import simulator_span, step_done, unit_started_at
from cloudsim.config import Config
from cloudsim.errors import CloudSimError
from cloudsim.extensions import db
from cloudsim.jobs.runner import JobContext, job_kind
from cloudsim.launched_constellations import router_control
from cloudsim.launched_constellations.connect import machine_host_keys, targets
from cloudsim.launched_constellations.keys import constellation_keypair
from cloudsim.models import Run, RunState, ScoreEvent, utcnow
from cloudsim.notifications.service import notify_run_event, run_ended_event
from cloudsim.worlds.service import world_for_run
from provisioners.remote.ssh import ConnectPolicy, HostKeys, SSHError, SSHExecutor, SSHTarget

ROUTER_FAULT = "router fault (OCU traffic is held until it is fixed): "
DRCSIM = "/opt/drcsim/bin/drcsim"
STOP_TIMEOUT_S = 60


class RunError(CloudSimError):
    """A step of a run's start or stop failed; the message says which and why."""


def unit_name(run_id: int) -> str:
    """Return the systemd unit the run's simulator runs as on `sim`."""
    return f"drcsim-run-{run_id}"


@dataclass(frozen=True)
class RunTargets:
    """How to reach a run's constellation: a target per machine, its host keys, its login key."""

    sim: SSHTarget
    router: SSHTarget | None
    sim_ip: str
    by_name: dict[str, SSHTarget]
    host_keys: HostKeys
    private_key: str = field(repr=False)
    fc_names: tuple[str, ...] = ()


@dataclass
class Machines:
    """SSH to a run's constellation: the executor and a target per role."""

    executor: SSHExecutor
    sim: SSHTarget
    router: SSHTarget | None
    sim_ip: str
    by_name: dict[str, SSHTarget]
    fc_names: tuple[str, ...] = ()

    @property
    def field_computers(self) -> list[SSHTarget]:
        """Return the field computers (team code runs there)."""
        return [self.by_name[name] for name in self.fc_names if name in self.by_name]

    def by_role(self) -> dict[str, SSHTarget]:
        """Return a target per source of run logs: sim, router, and each field computer."""
        found = {"sim": self.sim}
        if self.router is not None:
            found["router"] = self.router
        for name in self.fc_names:
            if name in self.by_name:
                found[name] = self.by_name[name]
        return found


def run_targets(run: Run, config: Config) -> RunTargets:
    """Return the SSH targets of the run's sim and router, from the machines' rows."""
    constellation = run.constellation
    if constellation is None:
        raise RunError(f"run {run.id}: its constellation no longer exists")
    keys = constellation_keypair(constellation)
    reach = targets(constellation, keys, config)
    by_role = {m.role: m for m in constellation.machines}
    sim = by_role.get("sim")
    if sim is None or not sim.private_ip:
        raise RunError(f"{constellation.name} has no simulator machine")
    router = by_role.get("router")
    return RunTargets(
        sim=reach[sim.name],
        router=reach[router.name] if router is not None else None,
        sim_ip=sim.private_ip,
        by_name=reach,
        host_keys=machine_host_keys(constellation),
        private_key=keys.private,
        fc_names=tuple(m.name for m in constellation.machines if m.role == "fc"),
    )


@contextmanager
def machines(
    run: Run,
    config: Config,
    ctx: JobContext | None = None,
    sink: Callable[[str, str], None] | None = None,
) -> Iterator[Machines]:
    """Connect to the run's sim and router; output lines go to the job log or to `sink`."""
    found = run_targets(run, config)
    executor = SSHExecutor(
        found.host_keys,
        log_sink=ctx.line_sink() if ctx else sink,
        secrets=[found.private_key],
        connect_policy=ConnectPolicy(deadline=60),
    )
    with executor:
        yield Machines(
            executor=executor,
            sim=found.sim,
            router=found.router,
            sim_ip=found.sim_ip,
            by_name=found.by_name,
            fc_names=found.fc_names,
        )


def simulator_command(run: Run, sim_ip: str, allow: list[str]) -> str:
    """Return the shell command that writes the run's world document into its folder and
    starts the simulator on it as a transient service."""
    task = run.task
    folder = run_dir(run.id)
    world = world_for_run(task.world, task.run_config)
    world_file = f"{folder}/{WORLD}"
    argv = [
        "systemd-run",
        f"--unit={unit_name(run.id)}",
        "--collect",
        "--property=KillSignal=SIGTERM",
        f"--property=TimeoutStopSec={STOP_TIMEOUT_S}",
        f"--property=StandardOutput=append:{folder}/simulator.log",
        f"--property=StandardError=append:{folder}/simulator.log",
        *serve_argv(
            DRCSIM,
            task.world,
            task.run_config,
            bind=sim_ip,
            allow=allow,
            log_dir=folder,
            time_limit_s=task.timeout_s,
            world_file=world_file,
        ),
    ]
    document = json.dumps(world.document, separators=(",", ":"))
    return (
        f"mkdir -p {shlex.quote(folder)} && printf '%s\\n' {shlex.quote(document)} > "
        f"{shlex.quote(world_file)} && " + " ".join(map(shlex.quote, argv))
    )


def _allowed_networks(run: Run) -> list[str]:
    resources = run.constellation.resources if run.constellation else {}
    # OCU traffic reaches sim from the router's LAN address (masqueraded), so the LAN covers it
    networks = [resources.get("subnet"), resources.get("vpn_network")]
    return [n for n in networks if n]


def router_run_id(run: Run) -> str:
    """Return the run's name on its router (csrouter's run id)."""
    return f"run-{run.id}"


@job_kind("run.start", payload=RunJob)
def start_run_job(ctx: JobContext, job: RunJob) -> None:
    """Arm the router, start the simulator, tell the field computers; the run is then
    `running` until the beat ends it. A resumed start finds what was done and goes on."""
    run = ctx.load(Run, job.run_id)
    if run.state != RunState.STARTING:
        ctx.log(f"run {run.id} is {run.state.value}; nothing to start")
        return
    step_done("run.start", "claimed")
    config: Config = current_app.config["CLOUDSIM"]
    task = run.task
    try:
        with machines(run, config, ctx) as reach:
            if reach.router is not None:
                # counting and capped before the simulator exists: no second of it unmetered
                _next_step(ctx, run, "router", 20)
                limits = router_control.Limits(
                    task.latency_ms, task.uplink_bits, task.downlink_bits
                )
                router_control.ensure_armed(
                    reach.executor, reach.router, limits, router_run_id(run)
                )
                step_done("run.start", "router")
            _next_step(ctx, run, "simulator", 60)
            run.running_at = _start_simulator(reach, run)
            step_done("run.start", "simulator")
            _next_step(ctx, run, "announce", 80)
            current_run.announce(reach.executor, reach.field_computers, run, reach.sim_ip)
            step_done("run.start", "announce")
    except StopAsked as asked:
        # what was started (an armed router, a simulator) is the stop job's to undo
        ctx.log(f"stop asked while starting ({asked}): the stop job takes over")
        lifecycle.stopped_while_starting(run)
        return
    except (CloudSimError, SSHError, ValueError) as exc:
        db.session.rollback()
        run = ctx.load(Run, job.run_id)
        lifecycle.start_failed(run, f"starting failed at the {ctx.job.stage} stage: {exc}")
        ctx.log(f"start failed ({exc}); stopping what was started")
        ctx.checkpoint()  # the stopping state and the stop job survive this job's failure
        raise RunError(run.error) from exc
    lifecycle.running(run)
    notify_run_event(run, "started")  # sent by its own tasks once this job commits
    ctx.stage("running", 100)
    lifecycle.stop_requested_while_starting(run)


class StopAsked(Exception):
    """The run was asked to stop while its start job was on its way; the reason is the arg."""


def _next_step(ctx: JobContext, run: Run, stage: str, progress: int) -> None:
    """Enter a step of the start, unless the run was asked to stop meanwhile (read now, on a
    connection of its own: the start job's transaction would not see the request)."""
    with db.engine.connect() as conn:
        reason = conn.scalar(select(Run.stop_reason).where(Run.id == run.id))
    if reason is not None:
        raise StopAsked(reason)
    ctx.stage(stage, progress)


def _start_simulator(reach: Machines, run: Run) -> datetime:
    """Start the run's simulator unless it runs (or ran) already; return when it started."""
    unit = shlex.quote(unit_name(run.id))
    final = shlex.quote(f"{run_dir(run.id)}/{FINAL}")
    state = reach.executor.run(
        reach.sim,
        f"systemctl is-active --quiet {unit} && echo active || (test -f {final} && echo ended)"
        " || echo absent",
        timeout=30,
    ).stdout.strip()
    if state in ("active", "ended"):
        reach.executor.log(reach.sim.name, f"simulator of run {run.id} already {state}")
        started = unit_started_at(reach.executor, reach.sim, unit_name(run.id))
        return started or run.running_at or utcnow()
    command = simulator_command(run, reach.sim_ip, _allowed_networks(run))
    world = world_for_run(run.task.world, run.task.run_config)
    reach.executor.log(
        reach.sim.name, f"world {world.name} version {world.version} ({world.digest[:12]})"
    )
    reach.executor.run(reach.sim, command, timeout=60)
    return utcnow()


@job_kind("run.stop", payload=RunJob)
def stop_run_job(ctx: JobContext, job: RunJob) -> None:
    """Stop the simulator, disarm the router, collect and score the logs, finish the run."""
    run = ctx.load(Run, job.run_id)
    if run.state in (RunState.FINISHED, RunState.ERROR, RunState.NEEDS_REVIEW):
        ctx.log(f"run {run.id} is {run.state.value} already")
        return
    lifecycle.stopping(run)
    ctx.checkpoint()
    step_done("run.stop", "claimed")
    config: Config = current_app.config["CLOUDSIM"]
    # A router fault seen during the run is kept on the record; it does not fail the run.
    router_note = run.error if run.error and run.error.startswith(ROUTER_FAULT) else None
    problems: list[str] = [run.error] if run.error and not router_note else []
    store = LogStore(config)
    try:
        with machines(run, config, ctx) as reach:
            problems += _stop_on_machines(ctx, run, reach, store, config)
    except (CloudSimError, SSHError) as exc:
        problems.append(f"{ctx.job.stage}: {exc}")
    ctx.stage("score", 90)
    score_run(run, store)
    run = ctx.load(Run, job.run_id)
    error = "; ".join([*problems, *([router_note] if router_note else [])])[:4000] or None
    if problems and run.running_at is not None and artifact_for(run, SCORE) is None:
        # it ran, but without its score log nobody can say how it ended: officers settle it
        lifecycle.needs_review(run, error or "the score log could not be collected")
        ctx.log(f"run {run.id} needs review: {run.error}")
        return
    lifecycle.ended(run, error, failed=bool(problems))
    notify_run_event(run, run_ended_event(run))  # sent by its own tasks once this job commits
    ctx.log(f"run {run.id} {run.state.value}: {run.score} checkpoint(s), ended by {run.end_reason}")


def _stop_on_machines(
    ctx: JobContext, run: Run, reach: Machines, store: LogStore, config: Config
) -> list[str]:
    problems = []
    ctx.stage("simulator", 10)
    unit = shlex.quote(unit_name(run.id))
    try:
        # SIGTERM: the simulator ends the run ("closed") and writes its final record
        reach.executor.run(reach.sim, f"systemctl stop {unit} || true", timeout=STOP_TIMEOUT_S + 30)
    except SSHError as exc:
        problems.append(f"simulator: {exc}")
    step_done("run.stop", "simulator")
    try:
        current_run.withdraw(reach.executor, reach.field_computers)
    except SSHError as exc:
        problems.append(f"current-run.json: {exc}")
    step_done("run.stop", "withdrawn")
    try:
        snapshot_login_logs(reach.executor, reach.field_computers, run.id)
    except SSHError as exc:
        problems.append(f"login records: {exc}")
    if reach.router is not None:
        # disarmed only once the simulator has stopped: its caps held to its last second
        ctx.stage("router", 30)
        span: tuple[float, float] | None = None
        try:
            span = simulator_span(reach.executor, reach.sim, run)
        except SSHError as exc:
            problems.append(f"the simulator's span: {exc}")
        try:  # disarmed even when sim does not answer: an armed router would go on counting
            router_control.ensure_disarmed(
                reach.executor, reach.router, router_run_id(run), covering=span[1] if span else None
            )
        except CloudSimError as exc:
            problems.append(str(exc))
        step_done("run.stop", "router")
        try:
            # however late the disarm came (a resumed stop), the run's log ends with the run
            span = span or simulator_span(reach.executor, reach.sim, run)
            destination = f"{run_dir(run.id)}/bandwidth.jsonl"
            router_control.save_run_log(
                reach.executor, reach.router, router_run_id(run), span, destination
            )
        except (CloudSimError, SSHError) as exc:
            problems.append(f"bandwidth log: {exc}")
        step_done("run.stop", "bandwidth")
    ctx.stage("logs", 50)
    staging = config.instance_dir / "staging" / "runs" / str(run.id)
    problems += collect_logs(
        run,
        reach.executor,
        reach.by_role(),
        store,
        staging,
        lambda line: ctx.log(line),
        ran=run.running_at is not None,
    )
    try:  # the router's bandwidth as MCAP, beside the simulator's run.mcap
        made = store_bandwidth_mcap(run, store, staging)
    except (OSError, McapError) as exc:
        problems.append(f"{BANDWIDTH_MCAP}: {exc}")
    else:
        if made:
            ctx.log(made)
    step_done("run.stop", "logs")
    return problems


def score_run(run: Run, store: LogStore) -> None:
    """Set the run's score, falls, time and bits used from its stored logs (again if repeated)."""
    score = artifact_for(run, SCORE)
    if score is not None:
        result = read_score_log(store.lines(score.location))
        db.session.query(ScoreEvent).filter_by(run_id=run.id).delete()
        for event in result.events:
            db.session.add(
                ScoreEvent(
                    run_id=run.id,
                    kind=event.kind,
                    checkpoint=event.checkpoint,
                    points=event.points,
                    sim_time=event.sim_time,
                    wall_time=event.wall_time,
                    description=event.description,
                )
            )
        run.score, run.falls = result.score, result.falls
        run.sim_seconds = result.sim_seconds
        run.end_reason = _end_reason(result.end_reason, run.stop_reason)
    bandwidth = artifact_for(run, "bandwidth.jsonl")
    if bandwidth is not None:
        usage = read_bandwidth_log(store.lines(bandwidth.location))
        run.uplink_bits_used = usage["uplink"].used_bits
        run.downlink_bits_used = usage["downlink"].used_bits
        run.uplink_spent_at = run.uplink_spent_at or usage["uplink"].spent_at
        run.downlink_spent_at = run.downlink_spent_at or usage["downlink"].spent_at
    db.session.flush()


def _end_reason(simulator: str | None, requested: str | None) -> str | None:
    """Prefer why CloudSim stopped the run over the simulator's "closed" (it was told to)."""
    if simulator in (None, "closed", "stopped") and requested:
        return requested
    return simulator
