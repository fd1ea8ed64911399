"""Facts a run's start and stop read from its machines before they act, and the step hooks.

Each step of `run.start` and `run.stop` looks at the machines first (is the router armed for
this run, is the simulator's unit active, when did the simulator start and end) and then does
only what is missing, so a job resumed after its worker died finds what the dead attempt did
and goes on from there (docs/metering.md).
"""

from __future__ import annotations

import shlex
from collections.abc import Callable
from datetime import UTC, datetime

from drcsim.rundir import SCORE, STATE, read_run_span

from cloudsim.competition.artifacts import run_dir
from cloudsim.models import Run, utcnow
from provisioners.remote.ssh import SSHExecutor, SSHTarget

# Called with (job kind, step) once a step of a run's start or stop is done. Production adds
# none; the crash tests add one that kills the worker there, to resume from every step.
STEP_HOOKS: list[Callable[[str, str], None]] = []
MTIME = "#mtime "


def step_done(kind: str, step: str) -> None:
    """Tell the step hooks that a step is done."""
    for hook in STEP_HOOKS:
        hook(kind, step)


def unit_started_at(executor: SSHExecutor, sim: SSHTarget, unit: str) -> datetime | None:
    """Return when systemd started the simulator's unit, None when it does not know it."""
    shown = executor.run(
        sim,
        f"systemctl show --property=ExecMainStartTimestamp --timestamp=unix --value "
        f"{shlex.quote(unit)} || true",
        timeout=30,
    ).stdout.strip()
    try:
        return datetime.fromtimestamp(float(shown.lstrip("@")), tz=UTC)
    except ValueError:
        return None  # "n/a", empty: the unit is gone


def simulator_span(executor: SSHExecutor, sim: SSHTarget, run: Run) -> tuple[float, float]:
    """Return when (epoch seconds) the run's simulator started and ended, from its score log;
    the end of a simulator that died before writing it is its state log's last write."""
    folder = run_dir(run.id)
    score, state = shlex.quote(f"{folder}/{SCORE}"), shlex.quote(f"{folder}/{STATE}")
    output = executor.run(
        sim,
        f'cat {score} 2>/dev/null; echo; echo "{MTIME}$(stat -c %.3Y {state} 2>/dev/null)"',
        timeout=120,
    ).stdout
    lines = output.splitlines()
    started, ended = read_run_span(lines)
    if ended is None:
        written = next((ln[len(MTIME) :] for ln in lines if ln.startswith(MTIME)), "")
        ended = float(written) if written.strip() else utcnow().timestamp()
    if started is None:
        started = run.running_at.timestamp() if run.running_at else ended
    return started, max(started, ended)
