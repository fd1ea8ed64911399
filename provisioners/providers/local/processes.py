"""Identify processes by PID, start time and boot, find a host's init, kill by recorded PID."""

import functools
import os
import signal
import time
from dataclasses import dataclass
from pathlib import Path

from provisioners.providers.local.errors import HostStopError

PROC = Path("/proc")
POLL_SECONDS = 0.05


@dataclass(frozen=True)
class ProcessId:
    """A PID with its start time and the machine's boot: a recycled PID never passes for it."""

    pid: int
    start_time: int
    boot_id: str = ""


@functools.cache
def current_boot_id() -> str:
    """Return the kernel's id of this boot (start times restart from zero at every boot)."""
    return (PROC / "sys/kernel/random/boot_id").read_text().strip()


def start_time(pid: int) -> int | None:
    """Return the process's start time in clock ticks since boot, None when it is gone."""
    try:
        stat = (PROC / str(pid) / "stat").read_text()
    except (FileNotFoundError, ProcessLookupError):
        return None
    # The command name may contain spaces and parentheses: split after the last ')'.
    fields = stat[stat.rindex(")") + 2 :].split()
    if fields[0] == "Z":
        return None
    return int(fields[19])


def identify(pid: int) -> ProcessId | None:
    """Return the ProcessId of a live PID, None when it is gone."""
    started = start_time(pid)
    return None if started is None else ProcessId(pid, started, current_boot_id())


def is_alive(process: ProcessId) -> bool:
    """Say whether the recorded process still runs (same PID, start time and boot)."""
    # Records written before boot ids were kept have none: judge those by start time alone.
    if process.boot_id and process.boot_id != current_boot_id():
        return False
    return start_time(process.pid) == process.start_time


def children(pid: int) -> list[int]:
    """Return the PIDs of pid's direct children."""
    found: list[int] = []
    try:
        for task in (PROC / str(pid) / "task").iterdir():
            found.extend(int(child) for child in (task / "children").read_text().split())
    except (FileNotFoundError, ProcessLookupError):
        return []
    return found


def namespace_pids(pid: int) -> list[int]:
    """Return pid as seen from each nested PID namespace, outermost first."""
    try:
        status = (PROC / str(pid) / "status").read_text()
    except (FileNotFoundError, ProcessLookupError):
        return []
    for line in status.splitlines():
        if line.startswith("NSpid:"):
            return [int(value) for value in line.split()[1:]]
    return []


def find_namespace_init(launcher: ProcessId) -> ProcessId | None:
    """Return the first descendant of launcher that is PID 1 of a nested PID namespace."""
    pending = children(launcher.pid)
    while pending:
        pid = pending.pop(0)
        nested = namespace_pids(pid)
        if len(nested) > 1 and nested[-1] == 1:
            return identify(pid)
        pending.extend(children(pid))
    return None


def wait_until_gone(process: ProcessId, timeout: float) -> bool:
    """Poll until the process has exited; say whether it did before the timeout."""
    deadline = time.monotonic() + timeout
    while is_alive(process):
        if time.monotonic() >= deadline:
            return False
        time.sleep(POLL_SECONDS)
    return True


def signal_process(process: ProcessId, signal_number: int) -> bool:
    """Send a signal to the recorded process if it still runs; say whether it was sent."""
    if not is_alive(process):
        return False
    try:
        os.kill(process.pid, signal_number)
    except ProcessLookupError:
        return False
    return True


def kill(process: ProcessId, timeout: float) -> None:
    """SIGKILL the recorded process if it still runs and wait until it is gone."""
    if not signal_process(process, signal.SIGKILL):
        return
    if not wait_until_gone(process, timeout):
        raise HostStopError(f"process {process.pid} survived SIGKILL for {timeout:.0f} s")


def proportional_memory_kib(pid: int) -> int:
    """Return the process's proportional set size (PSS) in KiB, 0 when it is gone."""
    try:
        rollup = (PROC / str(pid) / "smaps_rollup").read_text()
    except (FileNotFoundError, ProcessLookupError, PermissionError):
        return 0
    for line in rollup.splitlines():
        if line.startswith("Pss:"):
            return int(line.split()[1])
    return 0
