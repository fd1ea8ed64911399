"""The verification job: re-simulate a finished run from its own logs and compare.

It takes the run's id, copies its logs out of the store (each checked against its recorded
checksum) beside the world document the master holds, commits, replays the command log with
`drcsim replay` in its own process, and records `verified` or `held` with the reason (also
when the replay could not run at all: killed, or past its time limit). It
changes nothing until that last step, so a job resumed after a crash simply starts over; any
worker runs it, and as many at once as the workers have processes.
"""

from __future__ import annotations

import shutil

from celery import shared_task
from flask import current_app

from cloudsim.competition.artifacts import LogStore
from cloudsim.competition.lifecycle import RunJob
from cloudsim.config import Config
from cloudsim.errors import CloudSimError
from cloudsim.jobs.runner import JobContext, job_kind
from cloudsim.models import Run, Verification
from cloudsim.verification import service
from cloudsim.verification.compare import Claim, claimed_events, differences, score_log_claim
from cloudsim.verification.evidence import Held, ReplayFailed, gather, replay, work_folder
from cloudsim.worlds.service import world_for_run


def run_claim(run: Run) -> Claim:
    """Return what the run's record claims (what ranks it)."""
    return Claim(
        "the run",
        run.score,
        run.falls,
        run.sim_seconds,
        run.end_reason,
        claimed_events(run.score_events),
    )


@job_kind(service.VERIFY, payload=RunJob)
def verify_run_job(ctx: JobContext, job: RunJob) -> None:
    """Replay a finished run from its logs; record it verified, or held with the reason."""
    run = ctx.load(Run, job.run_id)
    if run.verification is not Verification.VERIFYING:
        ctx.log(f"run {run.id} is {service.label(run.verification)}: nothing to do")
        return
    config: Config = current_app.config["CLOUDSIM"]
    folder = work_folder(config.instance_dir, run.id)
    verdict, reason = Verification.VERIFIED, None
    try:
        ctx.stage("logs", 10)
        try:
            world = world_for_run(run.task.world, run.task.run_config)
        except CloudSimError as exc:
            raise Held(f"the task's world is not held here: {exc}") from None
        evidence = gather(run, LogStore(config), world, folder)
        claims = [run_claim(run), score_log_claim(evidence.score_log)]
        ctx.checkpoint()  # no transaction stays open while the replay runs (minutes)
        ctx.stage("replay", 30)
        result = replay(evidence)
        ctx.log(
            f"replayed {result['steps']} steps ({result['states_checked']} states checked): "
            f"{result['score']} checkpoint(s), {result['falls']} fall(s), ended "
            f"{result['end_reason'] or 'from outside'}"
        )
        found = [problem for claim in claims for problem in differences(claim, result)]
        if found:
            verdict, reason = Verification.HELD, "; ".join(found)
    except Held as held:
        verdict, reason = Verification.HELD, str(held)
    except ReplayFailed as failed:
        # not proven either way: an officer looks (and can accept) rather than it waiting forever
        verdict, reason = Verification.HELD, f"the replay could not run: {failed}"
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    ctx.stage("decide", 95)
    run = ctx.load(Run, job.run_id)
    if run.verification is not Verification.VERIFYING:
        ctx.log(f"run {run.id} became {service.label(run.verification)} meanwhile: kept")
        return
    service.decide(run, verdict, reason)
    ctx.log(f"run {run.id}: {service.label(verdict)}" + (f" ({reason})" if reason else ""))


@shared_task(name=service.SWEEP)
def sweep_verifications() -> int:
    """Queue the verification of finished runs that have none yet (beat)."""
    return service.sweep()
