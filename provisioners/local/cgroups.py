"""Per-host cgroups, so that systemd inside one host never manages another host's processes.

systemd-nspawn --keep-unit puts its container under the caller's own cgroup ("payload/").
Two hosts started by the same process would share it, and each host's systemd would see
(and stop) the other's services. Each launcher therefore first moves into a cgroup of its own.
"""

import errno
import os
import time
from pathlib import Path

from provisioners.local.errors import HostStopError

PROC_SELF = Path("/proc/self")
POLL_SECONDS = 0.05


def host_cgroup_dirs(machine: str, proc: Path = PROC_SELF) -> tuple[Path, ...]:
    """Return the cgroup dirs a host's launcher should join: one per systemd-relevant hierarchy.

    Those are the cgroup2 hierarchy and the cgroup v1 "name=systemd" one, each taken below this
    process's current cgroup there.
    """
    own_paths: dict[str, str] = {}
    for line in (proc / "cgroup").read_text().splitlines():
        hierarchy_id, controllers, path = line.split(":", 2)
        if hierarchy_id == "0":
            own_paths["cgroup2"] = path
        elif "name=systemd" in controllers.split(","):
            own_paths["name=systemd"] = path
    dirs: list[Path] = []
    for line in (proc / "mountinfo").read_text().splitlines():
        fields, _, after = line.partition(" - ")
        mount_root, mount_point = fields.split()[3:5]
        fstype, _source, options = after.split()[:3]
        kind = "cgroup2" if fstype == "cgroup2" else None
        if fstype == "cgroup" and "name=systemd" in options.split(","):
            kind = "name=systemd"
        if kind is None or kind not in own_paths:
            continue
        relative = os.path.relpath(own_paths.pop(kind), mount_root)
        dirs.append(Path(os.path.normpath(Path(mount_point) / relative / machine)))
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
