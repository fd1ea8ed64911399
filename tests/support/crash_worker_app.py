"""The test worker app, made to die (SIGKILL, pool process and worker) right after a step.

CLOUDSIM_TEST_CRASH_AFTER="run.start:router" kills the worker the moment the router step of
a run's start is done, as a crash there would; the job is then resumed by another worker.
"""

import os
import signal

from cloudsim.competition.run_steps import STEP_HOOKS
from tests.support.worker_app import celery_app, flask_app

CRASH_AFTER = os.environ.get("CLOUDSIM_TEST_CRASH_AFTER", "")


def _crash(kind: str, step: str) -> None:
    if f"{kind}:{step}" == CRASH_AFTER:
        os.kill(os.getppid(), signal.SIGKILL)  # the worker first: it would start a new pool
        os.kill(os.getpid(), signal.SIGKILL)


STEP_HOOKS.append(_crash)
__all__ = ["celery_app", "flask_app"]
