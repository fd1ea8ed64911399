"""The beat's watch over live runs: every machine asked at once, over connections kept open.

A worker process keeps one SSH connection per machine between beats (the SSH executor's
process cache) and a pool of threads. A beat asks every live run's sim (its score log, whether
the simulator still runs) and router (bits used, faults) at once, waits for the answers at most
`CLOUDSIM_RUN_PROBE_SECONDS`, and applies what came back. A machine that has not answered by
then is reported late: its question stays out (it is not asked again meanwhile, and may take
up to COMMAND_SECONDS there) and the beat that finds its answer applies it, so a slow or hung
machine never delays the other runs.
"""

from __future__ import annotations

import logging
import os
import shlex
import time
from concurrent.futures import Future, ThreadPoolExecutor, wait
from dataclasses import dataclass, field
from datetime import datetime, timedelta

from celery import shared_task
from csrouter.protocol import payload_bits_used, spent_at
from drcsim.rundir import FINAL, LIVE, SCORE, read_live, read_score_log
from flask import current_app
from sqlalchemy import select

from cloudsim.competition import lifecycle
from cloudsim.competition.artifacts import run_dir
from cloudsim.competition.jobs import ROUTER_FAULT, RunTargets, run_targets, unit_name
from cloudsim.config import Config
from cloudsim.error_codes import RUN_ROUTER_FAULT
from cloudsim.errors import CloudSimError
from cloudsim.extensions import db
from cloudsim.launched_constellations import router_control
from cloudsim.launched_constellations.connect import forget_gone_connections
from cloudsim.models import Job, JobState, Run, RunState, utcnow
from provisioners.remote.ssh import (
    CacheStats,
    ConnectionCache,
    ConnectPolicy,
    SSHError,
    SSHExecutor,
    SSHTarget,
    process_cache,
)

log = logging.getLogger(__name__)
MAX_STOP_ATTEMPTS = 3
# machines one worker process asks at once; with more live machines the rest wait their turn
PROBE_THREADS = 32
# how long a question may take on the machine, and reaching it (a late answer still counts)
COMMAND_SECONDS = 30
REACH = ConnectPolicy(deadline=30.0, attempt_timeout=10.0)


@dataclass(frozen=True)
class SimAnswer:
    """What `sim` said: the score log so far, and whether the simulator has ended."""

    score_lines: list[str]
    ended: bool
    sim_time: float = 0.0  # from its live figures: the score log's last event may be old


@dataclass(frozen=True)
class RouterAnswer:
    """What the router said: bits used and when a cap was spent, its daemon's faults."""

    used: dict[str, int] | None
    spent: dict[str, datetime | None]
    faults: list[str]


@dataclass
class BeatReport:
    """What one beat did and how long it took."""

    runs: int = 0  # live runs looked at
    asked: int = 0  # machines asked in this beat
    answered: int = 0  # answers applied, late ones from earlier beats included
    late: list[int] = field(default_factory=list)  # runs with a machine still not answering
    failed: dict[int, str] = field(default_factory=dict)  # runs whose machine answered an error
    stopped: int = 0  # stop jobs started
    seconds: float = 0.0
    connections: CacheStats | None = None


class Supervisor:
    """One worker process's supervision: its threads, its questions still out, its connections."""

    def __init__(
        self,
        connections: ConnectionCache,
        threads: int = PROBE_THREADS,
        command_seconds: int = COMMAND_SECONDS,
        reach: ConnectPolicy = REACH,
    ) -> None:
        self.connections = connections
        self.pid = os.getpid()
        self._command_seconds = command_seconds
        self._reach = reach
        self._pool = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="supervise")
        self._out: dict[tuple[int, str], Future[SimAnswer | RouterAnswer]] = {}

    def beat(self, config: Config) -> BeatReport:
        """Check every running run once; start the stop job of those that must end."""
        started = time.monotonic()
        report = BeatReport()
        self.connections.max_size = config.ssh_connections
        self.connections.prune()
        forget_gone_connections(self.connections)
        runs, must_end = _runs_to_ask(config, report)
        answers = {key: future for key, future in self._out.items() if future.done()}
        for key in answers:
            del self._out[key]
        asked: dict[tuple[int, str], Future[SimAnswer | RouterAnswer]] = {}
        for run in runs.values():
            try:
                found = run_targets(run, config)
            except (CloudSimError, SSHError) as exc:
                report.failed[run.id] = str(exc)
                continue
            for role, target in _roles(found):
                if (run.id, role) not in self._out and (run.id, role) not in answers:
                    asked[run.id, role] = self._pool.submit(self._ask, run.id, role, target, found)
        report.asked = len(asked)
        if asked:
            wait(asked.values(), timeout=config.run_probe_seconds)
        for key, future in asked.items():
            (answers if future.done() else self._out)[key] = future
        # written only now: with SQLite, a write held open would block the threads recording
        # a machine's host key at first contact
        for run, reason in must_end:
            report.stopped += lifecycle.request_stop(run, reason)
        for (run_id, role), future in sorted(answers.items()):
            if run_id in runs:  # a run that ended meanwhile has nothing left to learn
                report.answered += 1
                report.stopped += _apply(runs[run_id], role, future, report)
        report.late = sorted({run_id for run_id, _ in self._out if run_id in runs})
        report.stopped += _retry_failed_stops()
        report.seconds = time.monotonic() - started
        report.connections = self.connections.stats()
        log.log(
            logging.INFO if report.runs else logging.DEBUG,  # a line per beat while runs live
            "supervision: %d live runs, %d machines asked, %d answers, late %s, %.3f s, %s",
            report.runs, report.asked, report.answered, report.late or "none",
            report.seconds, report.connections,
        )  # fmt: skip
        if report.late:
            log.warning("runs %s: a machine has not answered yet", report.late)
        return report

    def close(self) -> None:
        """Stop the threads once the questions still out are answered."""
        self._pool.shutdown(wait=True)

    def _ask(
        self, run_id: int, role: str, target: SSHTarget, found: RunTargets
    ) -> SimAnswer | RouterAnswer:
        """Ask one machine (in a pool thread: SSH only, no database)."""
        executor = SSHExecutor(
            found.host_keys,
            secrets=[found.private_key],
            connect_policy=self._reach,
            default_timeout=self._command_seconds,
            connections=self.connections,
        )
        try:
            if role == "sim":
                return ask_sim(executor, target, run_id)
            return ask_router(executor, target)
        except (CloudSimError, SSHError):
            # a broken or silent connection is not handed out again: the next beat reconnects
            self.connections.evict(target)
            raise


def _runs_to_ask(
    config: Config, report: BeatReport
) -> tuple[dict[int, Run], list[tuple[Run, str]]]:
    """Return the running runs to ask by id, and those the database alone says must end."""
    now = utcnow()
    runs: dict[int, Run] = {}
    must_end: list[tuple[Run, str]] = []
    for run in db.session.scalars(select(Run).where(Run.state == RunState.RUNNING)):
        report.runs += 1
        reason = run.stop_reason
        if reason is None and now >= run.task.window_stop:
            reason = "window"
        limit = timedelta(seconds=run.task.timeout_s + config.run_grace_seconds)
        if reason is None and now >= (run.running_at or run.started_at) + limit:
            reason = "timeout"
        if reason is None:
            runs[run.id] = run
        else:
            must_end.append((run, reason))
    return runs, must_end


def _roles(found: RunTargets) -> list[tuple[str, SSHTarget]]:
    return [("sim", found.sim)] + ([("router", found.router)] if found.router else [])


def ask_sim(executor: SSHExecutor, sim: SSHTarget, run_id: int) -> SimAnswer:
    """Read the run's score log on `sim`, and whether its simulator has ended."""
    folder = run_dir(run_id)
    unit = shlex.quote(unit_name(run_id))
    command = (
        f"cat {shlex.quote(f'{folder}/{LIVE}')} 2>/dev/null; echo; echo '#'; "
        f"cat {shlex.quote(f'{folder}/{SCORE}')} 2>/dev/null; echo '#'; "
        f"test -f {shlex.quote(f'{folder}/{FINAL}')} && echo final; "
        f"systemctl is-active --quiet {unit} || echo inactive"
    )
    output = executor.run(sim, command).stdout
    live_text, _, rest = output.partition("#\n")
    lines, _, status = rest.rpartition("#\n")
    figures = read_live(live_text.strip()) or {}
    ended = "final" in status or "inactive" in status
    return SimAnswer(lines.splitlines(), ended, float(figures.get("sim_time", 0.0)))


def ask_router(executor: SSHExecutor, router: SSHTarget) -> RouterAnswer:
    """Read the router's counters and its daemon's faults (errors become faults)."""
    used: dict[str, int] | None = None
    spent: dict[str, datetime | None] = {}
    try:
        counts = router_control.counters(executor, router)
        used = payload_bits_used(counts)
        spent = {d: _moment(when) for d, when in spent_at(counts).items()}
    except (CloudSimError, KeyError, TypeError, ValueError) as exc:
        # the run's end is still detected; only the live figure waits for the next beat
        log.warning("router %s: cannot read the counters: %s", router.name, exc)
    try:
        faults = [str(f) for f in router_control.status(executor, router).get("faults") or []]
    except CloudSimError as exc:
        faults = [str(exc)]
    return RouterAnswer(used, spent, faults)


def _apply(
    run: Run, role: str, future: Future[SimAnswer | RouterAnswer], report: BeatReport
) -> int:
    """Write one machine's answer on the run; return 1 if it started the run's stop job."""
    error = future.exception()
    if error is not None:
        log.warning("run %s: cannot check the %s: %s", run.id, role, error)
        report.failed[run.id] = f"{role}: {error}"
        return 0
    answer = future.result()
    if isinstance(answer, SimAnswer):
        result = read_score_log(answer.score_lines)
        run.score, run.falls = result.score, result.falls
        run.sim_seconds = max(result.sim_seconds, answer.sim_time)
        db.session.flush()
        return lifecycle.request_stop(run, "ended") if answer.ended else 0
    if answer.used is not None:
        run.uplink_bits_used = answer.used["uplink"]
        run.downlink_bits_used = answer.used["downlink"]
        run.uplink_spent_at = run.uplink_spent_at or answer.spent.get("uplink")
        run.downlink_spent_at = run.downlink_spent_at or answer.spent.get("downlink")
    if answer.faults:
        run.error, run.error_code = ROUTER_FAULT + "; ".join(answer.faults), RUN_ROUTER_FAULT
        log.warning("run %s: %s", run.id, run.error)
    elif run.error and run.error.startswith(ROUTER_FAULT):
        run.error, run.error_code = None, None
    db.session.flush()
    return 0


def _moment(text: str | None) -> datetime | None:
    """Return csrouter's ISO 8601 time as a datetime (None stays None)."""
    return datetime.fromisoformat(text) if text else None


def _retry_failed_stops() -> int:
    """Start the stop job again for runs left `stopping` by a stop job that failed."""
    retried = 0
    for run in db.session.scalars(select(Run).where(Run.state == RunState.STOPPING)).all():
        jobs = list(
            db.session.scalars(
                select(Job)
                .where(Job.kind == "run.stop", Job.target_type == "run", Job.target_id == run.id)
                .order_by(Job.created_at.desc())
            )
        )
        if jobs and jobs[0].state == JobState.FAILED and len(jobs) < MAX_STOP_ATTEMPTS:
            log.warning("run %s: stop job failed (%s); starting it again", run.id, jobs[0].error)
            lifecycle.enqueue_stop(run)
            retried += 1
        elif jobs and jobs[0].state == JobState.FAILED:
            why = f"its stop failed {len(jobs)} times, last: {jobs[0].error}"
            log.warning("run %s: %s; it needs an officer's review", run.id, why)
            lifecycle.needs_review(run, why[:4000])
    return retried


_supervisor: Supervisor | None = None


def supervisor() -> Supervisor:
    """Return this process's supervisor (a forked worker process makes its own)."""
    global _supervisor
    if _supervisor is None or _supervisor.pid != os.getpid():
        _supervisor = Supervisor(process_cache())
    return _supervisor


@shared_task(name="cloudsim.competition.supervise")
def supervise_runs() -> int:
    """Start the stop job of every live run that must end; return how many were started."""
    return supervisor().beat(current_app.config["CLOUDSIM"]).stopped
