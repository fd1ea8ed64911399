"""The season in miniature for `make run`: a task open now, run by the example controller.

`schedule_demo(team_id, constellation_id)` schedules the task and starts a job that waits for
the constellation to be ready, starts the run, and starts the simulator's example controller
on `fc1`, which drives the robot over the LAN. The beat then ends the run at its time limit;
its score, plots and logs appear on the run page.
"""

from __future__ import annotations

import shlex
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import timedelta

from flask import current_app
from sqlalchemy import select

from cloudsim.auth.policy import SYSTEM
from cloudsim.competition.jobs import DRCSIM, RunError, machines
from cloudsim.competition.runs import start_run
from cloudsim.competition.schedule import TaskSpec, schedule
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.jobs.runner import JobContext, Payload, job_kind
from cloudsim.jobs.service import enqueue
from cloudsim.models import Constellation, ConstellationState, Job, Run, RunState, Task, utcnow

DEMO_TASK = "Demo: walking"
DEMO_WORLD = "vrc_task_2"
DEMO_SECONDS = 60  # simulated; the example controller finishes the walk in about 35 s
WAIT_S = 1800
POLL_S = 2.0


def schedule_demo(team_id: int, constellation_id: int) -> Job:
    """Schedule the demo task for the team (once) and start the job that runs it."""
    task = db.session.scalar(select(Task).where(Task.team_id == team_id, Task.name == DEMO_TASK))
    if task is None:
        now = utcnow()
        spec = TaskSpec(
            name=DEMO_TASK,
            world=DEMO_WORLD,
            run_config=1,
            window_start=now - timedelta(minutes=1),
            window_stop=now + timedelta(hours=12),
            timeout_s=DEMO_SECONDS,
        )
        [task] = schedule(SYSTEM, spec, [team_id])
    return enqueue("competition.demo", SYSTEM, DemoJob(task.id, constellation_id), team_id=team_id)


@dataclass(frozen=True)
class DemoJob(Payload):
    """The demo job's payload: the demo task and the constellation to run it on."""

    task_id: int
    constellation_id: int

    def about(self) -> tuple[str, int]:
        return ("task", self.task_id)


@job_kind("competition.demo", payload=DemoJob)
def run_demo(ctx: JobContext, job: DemoJob) -> None:
    """Wait for the constellation, start the demo run, start the example controller on fc1."""
    task = ctx.load(Task, job.task_id)
    constellation_id = job.constellation_id
    ctx.stage("constellation", 10)
    _await(ctx, lambda: _ready(constellation_id), "the constellation to be ready")
    run = db.session.scalar(select(Run).where(Run.task_id == task.id).order_by(Run.id.desc()))
    if run is not None and run.state in (RunState.STOPPING, RunState.FINISHED):
        ctx.log(f"the demo run {run.id} has run already ({run.state.value})")
        return
    if run is None or run.state == RunState.ERROR:
        ctx.stage("start", 40)
        run = start_run(SYSTEM, task.id, constellation_id)
        ctx.checkpoint()  # the run exists and its start job is sent before this job waits
        ctx.log(f"started run {run.id}")
    run_id = run.id
    _await(ctx, lambda: _state(run_id) != RunState.STARTING, f"run {run_id} to start")
    if _state(run_id) != RunState.RUNNING:
        raise RunError(f"run {run_id} did not start: {db.session.get(Run, run_id).error}")  # type: ignore[union-attr]
    ctx.stage("controller", 80)
    config: Config = current_app.config["CLOUDSIM"]
    run = db.session.get(Run, run_id)
    assert run is not None
    with machines(run, config, ctx) as reach:
        fc1 = reach.by_name.get("fc1", reach.sim)
        unit = shlex.quote(f"example-controller-{run_id}")
        reach.executor.run(
            fc1,
            f"systemctl is-active --quiet {unit} || systemd-run --unit={unit} --collect "
            f"{DRCSIM} example-controller --server {shlex.quote(reach.sim_ip)} "
            f"--world {shlex.quote(task.world)} --timeout {DEMO_SECONDS * 3}",
            timeout=30,
        )
    ctx.log(f"the example controller drives run {run_id} from {fc1.name}")


def _ready(constellation_id: int) -> bool:
    constellation = db.session.get(Constellation, constellation_id)
    if constellation is None or constellation.state in (
        ConstellationState.ERROR,
        ConstellationState.TERMINATING,
        ConstellationState.TERMINATED,
        ConstellationState.TERMINATE_INCOMPLETE,
    ):
        state = constellation.state.value if constellation else "gone"
        raise RunError(f"the demo constellation is {state}")
    return constellation.state == ConstellationState.READY


def _state(run_id: int) -> RunState:
    run = db.session.get(Run, run_id)
    assert run is not None
    return run.state


def _await(ctx: JobContext, condition: Callable[[], bool], what: str) -> None:
    deadline = time.monotonic() + WAIT_S
    while True:
        db.session.expire_all()
        if condition():
            return
        if time.monotonic() > deadline:
            raise RunError(f"gave up waiting for {what} after {WAIT_S} s")
        ctx.progress(ctx.job.progress)  # keeps the row fresh for the page
        time.sleep(POLL_S)
