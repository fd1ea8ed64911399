"""Who logged into the field computers: each one's login record, kept with the run's logs.

The field computers' PAM hook (constellations/plans/members.py) appends a line per SSH
session opened or closed, as root, naming the account and the member. When a run stops, the
record as it stands is copied into the run's folder on each field computer, once, so that
the log collection stores it beside the simulator's and the router's logs.
"""

from __future__ import annotations

import shlex

from cloudsim.competition.artifacts import LOGIN_LOG_NAME, run_dir
from constellations.plans.members import LOGIN_LOG
from provisioners.remote.ssh import SSHExecutor, SSHTarget


def snapshot_login_logs(
    executor: SSHExecutor, field_computers: list[SSHTarget], run_id: int
) -> None:
    """Copy each field computer's login record into the run's folder there, once (a resumed
    stop keeps the first copy, so its checksum holds); an empty one if nobody logged in."""
    folder = run_dir(run_id)
    for target in field_computers:
        name = LOGIN_LOG_NAME.format(machine=target.name.rsplit("/", 1)[-1])
        final = shlex.quote(f"{folder}/{name}")
        partial = shlex.quote(f"{folder}/.{name}.part")
        executor.run(
            target,
            f"mkdir -p {shlex.quote(folder)} && (test -f {final} || "
            f"((cat {shlex.quote(LOGIN_LOG)} 2>/dev/null || true) > {partial} && "
            f"mv {partial} {final}))",
            timeout=60,
        )
