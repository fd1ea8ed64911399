"""Per-host cgroups, so that hosts share no cgroup with each other or with their creator.

systemd-nspawn --keep-unit puts its container under the caller's own cgroup ("payload/"):
two hosts started by one process would share it, each host's systemd seeing the other's
services. And a service manager stopping the orchestrator kills its whole cgroup, hosts
included, although hosts must outlive it. So each launcher first moves into a cgroup of its
own at the top of the systemd-relevant hierarchies (cgroup2 and cgroup v1 "name=systemd").
"""

import errno
import os
import time
from pathlib import Path

from provisioners.providers.local.errors import HostStopError

PROC_SELF = Path("/proc/self")
POLL_SECONDS = 0.05


def host_cgroup_dirs(machine: str, proc: Path = PROC_SELF) -> tuple[Path, ...]:
    """Return the cgroup dirs a host's launcher joins: machine at the top of each hierarchy."""
    dirs: list[Path] = []
    for line in (proc / "mountinfo").read_text().splitlines():
        fields, _, after = line.partition(" - ")
        mount_point = fields.split()[4]
        fstype, _source, options = after.split()[:3]
        systemd_v1 = fstype == "cgroup" and "name=systemd" in options.split(",")
        if fstype == "cgroup2" or systemd_v1:
            dirs.append(Path(mount_point) / machine)
    return tuple(dirs)


def remove_cgroup_dirs(dirs: tuple[Path, ...], timeout: float) -> None:
    """Remove the host's cgroup dirs, children first, once their processes have exited."""
    deadline = time.monotonic() + timeout
    for top in dirs:
        if not top.is_dir():
            continue
        nested = [Path(root) for root, _subdirs, _files in os.walk(top, topdown=False)]
        for directory in nested:
            _remove_when_empty(directory, deadline)


def _remove_when_empty(directory: Path, deadline: float) -> None:
    while True:
        try:
            directory.rmdir()
            return
        except FileNotFoundError:
            return
        except OSError as error:
            # EBUSY: a process of the dead host has not been released from the cgroup yet.
            if error.errno != errno.EBUSY or time.monotonic() >= deadline:
                raise HostStopError(f"cannot remove cgroup {directory}: {error}") from error
        time.sleep(POLL_SECONDS)
