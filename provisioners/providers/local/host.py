"""Start and stop one host: overlay root, first boot, then systemd-nspawn -b or tini + sshd."""

import os
import re
import shutil
import signal
import stat
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

from provisioners.providers.local import boot_scripts, layers, processes
from provisioners.providers.local.commands import command_succeeds, run_command
from provisioners.providers.local.errors import CommandError, HostBootError, InvalidRequestError
from provisioners.providers.local.netns import can_connect, netns_path
from provisioners.providers.local.processes import ProcessId

INIT_SYSTEMD = "systemd"
INIT_MINIMAL = "minimal"
INIT_MODES = (INIT_SYSTEMD, INIT_MINIMAL)

SYSTEMD_BINARY = Path("/usr/lib/systemd/systemd")
NSPAWN_PROPAGATE_DIR = Path("/run/systemd/nspawn/propagate")
SSH_PORT = 22
SSH_UNIT = "ssh.service"
UNIT_CHECK_SECONDS = 1.0
# Units the base image enables that a host still needs: its sshd.
KEEP_ENABLED_UNITS = frozenset({"ssh.service", "sshd.service", "ssh.socket"})
# nspawn would start a getty on its (passive) console: nobody logs in there.
ALWAYS_MASKED_UNITS = ("console-getty.service",)
MASKABLE_SUFFIXES = (".service", ".timer", ".path", ".socket")
LAUNCH_SECONDS = 30.0
LAUNCHER_EXIT_SECONDS = 5.0
KILL_WAIT_SECONDS = 10.0
POLL_SECONDS = 0.05

# Paths of the controller that no host may read through the overlay's lower layer "/":
# its users' keys and dotfiles, server data, scratch space.
DEFAULT_HIDDEN_PATHS = (
    "/root",
    "/home",
    "/srv",
    "/tmp",  # noqa: S108 (hidden from hosts, not used)
    "/var/tmp",  # noqa: S108 (hidden from hosts, not used)
    "/var/backups",
    "/var/lib/postgresql",
    "/var/lib/redis",
    # Without its data dir the controller's cluster config would only confuse pg_ctlcluster.
    "/etc/postgresql",
)
OPAQUE_XATTR = "trusted.overlay.opaque"

_ANSI_ESCAPE = re.compile(r"\x1b\[[0-9;]*[A-Za-z]")


@dataclass(frozen=True)
class HostSpec:
    """Everything needed to boot one host."""

    hostname: str
    machine: str
    netns: str
    init: str
    host_dir: Path
    node_dir: Path
    machine_id: str
    hidden_paths: tuple[Path, ...] = ()
    cgroup_dirs: tuple[Path, ...] = ()

    @property
    def boot_log(self) -> Path:
        """Return the file collecting the launcher's and the host console's output."""
        return self.node_dir / "boot.log"

    @property
    def authorized_keys(self) -> Path:
        """Return the file whose content becomes /root/.ssh/authorized_keys in the host."""
        return self.node_dir / "authorized_keys"

    @property
    def launcher_pidfile(self) -> Path:
        """Return the file where the launcher writes its PID."""
        return self.node_dir / "launcher.pid"


@dataclass(frozen=True)
class HostProcesses:
    """The launcher (unshare or systemd-nspawn) and the host's init (PID 1 inside)."""

    launcher: ProcessId
    init: ProcessId


def systemd_boot_available() -> bool:
    """Say whether hosts can boot systemd (systemd-nspawn and systemd are installed)."""
    return shutil.which("systemd-nspawn") is not None and SYSTEMD_BINARY.exists()


def units_to_mask(systemd_dir: Path = Path("/etc/systemd/system")) -> list[str]:
    """Return the units the base image enables that a host must not start."""
    units = set(ALWAYS_MASKED_UNITS)
    for wants_dir in [*systemd_dir.glob("*.wants"), *systemd_dir.glob("*.requires")]:
        for link in wants_dir.iterdir():
            if link.name.endswith(MASKABLE_SUFFIXES) and link.name not in KEEP_ENABLED_UNITS:
                units.add(link.name)
    return sorted(units)


def hide_paths(upper: Path, hidden: tuple[Path, ...]) -> None:
    """Mask the lower layer at each path: an opaque empty directory, or a whiteout for files."""
    for path in hidden:
        if not path.is_absolute() or path == Path("/"):
            raise InvalidRequestError(f"cannot hide {str(path)!r} from hosts")
        try:
            lower = os.lstat(path)
        except FileNotFoundError:
            continue
        for ancestor in reversed(path.parents[:-1]):
            _mirror_directory(upper, ancestor)
        target = upper / path.relative_to("/")
        if stat.S_ISDIR(lower.st_mode):
            _mirror_directory(upper, path)
            os.setxattr(target, OPAQUE_XATTR, b"y")
        elif not os.path.lexists(target):
            # A 0/0 character device is overlayfs's whiteout: the file does not exist above.
            os.mknod(target, stat.S_IFCHR | 0o000, os.makedev(0, 0))


def _mirror_directory(upper: Path, path: Path) -> None:
    """Create path in the upper dir with the lower directory's mode and owner."""
    target = upper / path.relative_to("/")
    if target.exists():
        return
    lower = os.stat(path)
    target.mkdir()
    os.chown(target, lower.st_uid, lower.st_gid)
    target.chmod(stat.S_IMODE(lower.st_mode))


def launch_command(spec: HostSpec, masked_units: list[str]) -> list[str]:
    """Return the argv that boots the host and records the launcher's PID."""
    common = [str(spec.host_dir), spec.hostname, spec.machine, spec.machine_id]
    if spec.init == INIT_SYSTEMD:
        inner = [
            "env", "SYSTEMD_NSPAWN_API_VFS_WRITABLE=network",
            "unshare", "--mount", "--propagation", "private", "--",
            "bash", "-c", boot_scripts.SYSTEMD_BOOT, "host-boot",
            *common, str(spec.authorized_keys), spec.netns, *masked_units,
        ]  # fmt: skip
    else:
        inner = [
            "nsenter", f"--net={netns_path(spec.netns)}",
            "unshare", "--mount", "--uts", "--ipc", "--pid", "--fork", "--kill-child",
            "--propagation", "private", "--",
            "bash", "-c", boot_scripts.MINIMAL_INIT, "host-init",
            *common, str(spec.authorized_keys),
        ]  # fmt: skip
    # setsid -f detaches the launcher: it must outlive (and not be reaped by) this process.
    cgroups = [str(len(spec.cgroup_dirs)), *map(str, spec.cgroup_dirs)]
    return [
        "setsid", "-f", "bash", "-c", boot_scripts.LAUNCHER, "launcher",
        str(spec.launcher_pidfile), *cgroups, *inner,
    ]  # fmt: skip


def start_host(spec: HostSpec, timeout: float) -> HostProcesses:
    """Launch the host and return once its init runs; raise HostBootError otherwise."""
    for directory in ("upper", "work", "root"):
        (spec.host_dir / directory).mkdir(parents=True, exist_ok=True)
    upper = spec.host_dir / "upper"
    if not any(upper.iterdir()):
        # The upper dir's mode becomes the mode of the host's "/": it must match the real one.
        upper.chmod(0o755)
        hide_paths(upper, spec.hidden_paths)
    layers.record_lowerdir(spec.host_dir)
    masked = units_to_mask() if spec.init == INIT_SYSTEMD else []
    with open(spec.boot_log, "ab") as log:
        try:
            # Returns at once: setsid -f forks the launcher off and exits.
            subprocess.run(
                launch_command(spec, masked),
                stdin=subprocess.DEVNULL,
                stdout=log,
                stderr=subprocess.STDOUT,
                check=True,
                timeout=LAUNCH_SECONDS,
            )
        except (OSError, subprocess.SubprocessError) as error:
            raise HostBootError(f"host {spec.hostname}: cannot launch: {error}") from error
    deadline = time.monotonic() + timeout
    launcher = _wait_for_launcher(spec, deadline)
    while True:
        init = processes.find_namespace_init(launcher)
        if init is not None:
            return HostProcesses(launcher=launcher, init=init)
        if not processes.is_alive(launcher):
            raise HostBootError(f"host {spec.hostname}: the launcher exited before init started")
        if time.monotonic() >= deadline:
            raise HostBootError(f"host {spec.hostname}: init did not start in {timeout:.0f} s")
        time.sleep(POLL_SECONDS)


def _wait_for_launcher(spec: HostSpec, deadline: float) -> ProcessId:
    while True:
        text = spec.launcher_pidfile.read_text() if spec.launcher_pidfile.exists() else ""
        if text.endswith("\n"):
            launcher = processes.identify(int(text))
            if launcher is None:
                raise HostBootError(f"host {spec.hostname}: the launcher exited at once")
            return launcher
        if time.monotonic() >= deadline:
            raise HostBootError(f"host {spec.hostname}: the launcher did not start")
        time.sleep(POLL_SECONDS)


def wait_for_sshd(spec: HostSpec, host: HostProcesses, timeout: float) -> None:
    """Poll until sshd accepts TCP connections inside the host; raise HostBootError if not."""
    deadline = time.monotonic() + timeout
    next_unit_check = time.monotonic() + UNIT_CHECK_SECONDS
    while not can_connect(spec.netns, "127.0.0.1", SSH_PORT):
        if not processes.is_alive(host.init):
            raise HostBootError(f"host {spec.hostname}: init exited before sshd listened")
        if time.monotonic() >= deadline:
            raise HostBootError(f"host {spec.hostname}: sshd did not listen in {timeout:.0f} s")
        if spec.init == INIT_SYSTEMD and time.monotonic() >= next_unit_check:
            # systemd gives up on a unit that keeps failing: no point waiting for the deadline.
            if _unit_failed(host.init, SSH_UNIT):
                raise HostBootError(f"host {spec.hostname}: {SSH_UNIT} failed")
            next_unit_check = time.monotonic() + UNIT_CHECK_SECONDS
        time.sleep(POLL_SECONDS)


def _unit_failed(init: ProcessId, unit: str) -> bool:
    """Say whether systemd inside the host has given up on unit (state "failed")."""
    return command_succeeds(
        [*_enter_host(init), "systemctl", "is-failed", "--quiet", unit], timeout=10
    )


def _enter_host(init: ProcessId) -> list[str]:
    """Return the argv prefix that runs a command inside the host of this init."""
    return ["nsenter", f"--target={init.pid}", "--mount", "--pid", "--uts", "--ipc", "--net"]


def stop_host(launcher: ProcessId | None, init: ProcessId | None) -> None:
    """Kill the host's init (its whole PID namespace dies) and wait for the launcher to exit."""
    launcher_frozen = False
    if init is None and launcher is not None and processes.is_alive(launcher):
        # Init was never recorded: freeze the launcher so it cannot start one while we look.
        launcher_frozen = processes.signal_process(launcher, signal.SIGSTOP)
        init = processes.find_namespace_init(launcher)
    if init is not None:
        processes.kill(init, KILL_WAIT_SECONDS)
    if launcher is None:
        return
    # nspawn tidies up after its container died; only a stuck or frozen launcher gets SIGKILL.
    if launcher_frozen or not processes.wait_until_gone(launcher, LAUNCHER_EXIT_SECONDS):
        processes.kill(launcher, KILL_WAIT_SECONDS)


def boot_log_tail(spec: HostSpec, lines: int = 30) -> str:
    """Return the last lines of the host's boot log, without terminal colour codes."""
    if not spec.boot_log.exists():
        return "(no boot log)"
    text = _ANSI_ESCAPE.sub("", spec.boot_log.read_text(errors="replace"))
    return "\n".join(text.splitlines()[-lines:])


def systemd_journal_tail(init: ProcessId | None, lines: int = 30) -> str:
    """Return the end of a booting systemd host's journal, or why it could not be read."""
    if init is None or not processes.is_alive(init):
        return "(the host's init is not running)"
    command = [*_enter_host(init), "journalctl", "--boot", "--no-pager", f"--lines={lines}"]
    try:
        return run_command(command, timeout=10).rstrip()
    except CommandError as error:
        return f"(cannot read the host's journal: {error})"


def remove_host_files(spec: HostSpec) -> None:
    """Remove the host's overlay directories and nspawn's leftover propagation directory."""
    for directory in (spec.host_dir, NSPAWN_PROPAGATE_DIR / spec.machine):
        try:
            shutil.rmtree(directory)
        except FileNotFoundError:
            continue  # never made, or removed by a concurrent destroy of the same host


def mount_hosts_tmpfs(hosts_dir: Path, source: str) -> None:
    """Mount the tmpfs holding every host's overlay upper dir, unless already mounted."""
    hosts_dir.mkdir(parents=True, exist_ok=True)
    if not hosts_dir.is_mount():
        run_command(["mount", "-t", "tmpfs", "-o", "mode=700", source, str(hosts_dir)])


def unmount_hosts_tmpfs(hosts_dir: Path) -> None:
    """Unmount the hosts tmpfs; no-op when it is not mounted."""
    if hosts_dir.is_dir() and hosts_dir.is_mount():
        run_command(["umount", str(hosts_dir)])
