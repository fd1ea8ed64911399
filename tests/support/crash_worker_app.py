"""The test worker app, made to die (SIGKILL, pool process and worker) at a job's step.

CLOUDSIM_TEST_CRASH_AFTER="run.start:router" kills the worker the moment the router step of
a run's start is done (cloudsim.competition.run_steps); CLOUDSIM_TEST_CRASH_AT=
"constellation.launch:machines" the moment any job of that kind enters that stage
(cloudsim.jobs.runner). Another worker then resumes the job.
"""

import os
import signal

from cloudsim.competition.run_steps import STEP_HOOKS
from cloudsim.jobs.runner import STAGE_HOOKS
from tests.support.worker_app import celery_app, flask_app

CRASH_AFTER = os.environ.get("CLOUDSIM_TEST_CRASH_AFTER", "")
CRASH_AT = os.environ.get("CLOUDSIM_TEST_CRASH_AT", "")


def _die() -> None:
    os.kill(os.getppid(), signal.SIGKILL)  # the worker first: it would start a new pool
    os.kill(os.getpid(), signal.SIGKILL)


def _crash_after(kind: str, step: str) -> None:
    if f"{kind}:{step}" == CRASH_AFTER:
        _die()


def _crash_at(kind: str, stage: str) -> None:
    if f"{kind}:{stage}" == CRASH_AT:
        _die()


STEP_HOOKS.append(_crash_after)
STAGE_HOOKS.append(_crash_at)
__all__ = ["celery_app", "flask_app"]
