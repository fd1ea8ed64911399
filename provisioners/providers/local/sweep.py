"""Remove whatever carries a prefix but has no record any more (its state_dir was lost)."""

import shutil
from pathlib import Path

from provisioners.providers.local import netns, processes
from provisioners.providers.local.cgroups import remove_cgroup_dirs
from provisioners.providers.local.commands import run_command
from provisioners.providers.local.host import KILL_WAIT_SECONDS, NSPAWN_PROPAGATE_DIR

CGROUP_ROOT = Path("/sys/fs/cgroup")
MOUNTS = Path("/proc/mounts")


def sweep_prefix(prefix: str) -> list[str]:
    """Kill, delete and unmount every namespace, cgroup and hosts tmpfs named after prefix."""
    removed: list[str] = []
    owned = f"{prefix}-"
    for namespace in netns.list_namespaces(owned):
        _kill_namespace_processes(namespace)
        netns.delete_namespace(namespace)
        removed.append(f"netns {namespace}")
    cgroups = tuple(sorted(CGROUP_ROOT.glob(f"*/{owned}*")))
    for cgroup in cgroups:
        # Launchers (systemd-nspawn) live outside the host's namespaces, in its cgroup.
        for pid in _cgroup_pids(cgroup):
            launcher = processes.identify(pid)
            if launcher is not None:
                processes.kill(launcher, KILL_WAIT_SECONDS)
        removed.append(f"cgroup {cgroup}")
    remove_cgroup_dirs(cgroups, KILL_WAIT_SECONDS)
    for leftover in sorted(NSPAWN_PROPAGATE_DIR.glob(f"{owned}*")):
        # Left by hosts of versions that did not give nspawn a private propagation dir.
        shutil.rmtree(leftover)
        removed.append(f"directory {leftover}")
    for line in MOUNTS.read_text().splitlines():
        source, mount_point = line.split()[:2]
        if source == f"{prefix}-hosts":
            run_command(["umount", "--lazy", mount_point])
            removed.append(f"mount {mount_point}")
    return removed


def _kill_namespace_processes(namespace: str) -> None:
    """SIGKILL the PID-namespace inits living in the namespace first, then everything else."""
    members = [p for p in map(processes.identify, netns.namespace_pids(namespace)) if p]
    inits = [p for p in members if _is_namespace_init(p.pid)]
    for process in inits + [p for p in members if p not in inits]:
        processes.kill(process, KILL_WAIT_SECONDS)


def _is_namespace_init(pid: int) -> bool:
    nested = processes.namespace_pids(pid)
    return len(nested) > 1 and nested[-1] == 1


def _cgroup_pids(cgroup: Path) -> list[int]:
    pids: list[int] = []
    for procs in cgroup.glob("**/cgroup.procs"):
        pids.extend(int(pid) for pid in procs.read_text().split())
    return pids
