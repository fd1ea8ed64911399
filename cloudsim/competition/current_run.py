"""Tell team code on the field computers that a run is on: /var/lib/cloudsim/current-run.json.

Written (0644, readable by every member's account) once the simulator runs, removed when the run
stops. The simulator's own `hello` says the same from the API side.
"""

from __future__ import annotations

import json
import shlex
from datetime import timedelta

from drcsim.client import DEFAULT_COMMAND_PORT

from cloudsim.models import Run, utcnow
from constellations.plans.roles import RUN_STATE_DIR
from provisioners.remote.ssh import SSHExecutor, SSHTarget

CURRENT_RUN = f"{RUN_STATE_DIR}/current-run.json"


def current_run_document(run: Run, sim_ip: str) -> dict[str, object]:
    """Return what current-run.json says about a run that has just started."""
    task = run.task
    started = run.running_at or utcnow()
    return {
        "run_id": run.id,
        "task": task.name,
        "world": task.world,
        "config": task.run_config,
        "started_at": started.isoformat(),
        # at real time; the simulator ends the run at time_limit_s of simulated time
        "ends_at": (started + timedelta(seconds=task.timeout_s)).isoformat(),
        "time_limit_s": task.timeout_s,
        "window_closes_at": task.window_stop.isoformat(),
        # its hello answers the rest (the publish port, joints, topics, the course)
        "simulator": {"host": sim_ip, "command_port": DEFAULT_COMMAND_PORT},
    }


def announce(
    executor: SSHExecutor, field_computers: list[SSHTarget], run: Run, sim_ip: str
) -> None:
    """Write current-run.json on every field computer."""
    body = json.dumps(current_run_document(run, sim_ip), indent=2).encode() + b"\n"
    for target in field_computers:
        executor.run(target, f"mkdir -p -m 0755 {shlex.quote(RUN_STATE_DIR)}", timeout=30)
        executor.put_file(target, body, CURRENT_RUN, mode=0o644)


def withdraw(executor: SSHExecutor, field_computers: list[SSHTarget]) -> None:
    """Remove current-run.json from every field computer: no run is on."""
    for target in field_computers:
        executor.run(target, f"rm -f {shlex.quote(CURRENT_RUN)}", timeout=30)
