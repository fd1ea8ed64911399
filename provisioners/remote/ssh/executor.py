"""Run commands and move files on machines over SSH, logging everything with secrets masked."""

from __future__ import annotations

import hashlib
import os
import secrets as token_source
import select
import shlex
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path, PurePosixPath
from types import TracebackType
from typing import TypeVar

import fabric
import paramiko

from provisioners.remote.ssh.cache import ConnectionCache
from provisioners.remote.ssh.connections import ConnectionPool, ConnectPolicy, Interrupt
from provisioners.remote.ssh.errors import (
    CommandFailed,
    CommandTimeout,
    ConnectionLost,
    GroupError,
    SSHError,
)
from provisioners.remote.ssh.hostkeys import HostKeyStore
from provisioners.remote.ssh.output import LineStream, LogSink, SecretMasker
from provisioners.remote.ssh.result import CommandResult, Transfer
from provisioners.remote.ssh.target import SSHTarget

T = TypeVar("T")

_WINDOW = 4 << 20  # bytes of a download held in memory at most
_CHUNK = 64 * 1024
# after the timeout, `timeout` sends TERM, then KILL this many seconds later
_KILL_AFTER_SECONDS = 5
# exit codes of coreutils `timeout` when it stopped the command (TERM, then KILL)
_TIMEOUT_EXIT_CODES = frozenset({124, 137})
# extra wait on our side for a machine that stopped answering altogether
_CLIENT_GRACE_SECONDS = _KILL_AFTER_SECONDS + 5
# how often a running command checks whether its caller said stop
_INTERRUPT_POLL_SECONDS = 1.0


def _no_log(machine_name: str, line: str) -> None:
    del machine_name, line


class SSHExecutor:
    """Run commands and transfer files on machines, reusing one connection per machine."""

    def __init__(
        self,
        host_keys: HostKeyStore,
        *,
        log_sink: LogSink | None = None,
        secrets: Iterable[str] = (),
        connect_policy: ConnectPolicy | None = None,
        default_timeout: float = 600.0,
        max_parallel: int = 16,
        connections: ConnectionCache | None = None,
        interrupt: Interrupt | None = None,
    ) -> None:
        self._sink = log_sink or _no_log
        self._mask = SecretMasker(secrets)
        self._default_timeout = default_timeout
        self._max_parallel = max_parallel
        self._policy = connect_policy or ConnectPolicy()
        # the pinned host keys, also for transports that do not go through paramiko
        self.host_keys = host_keys
        # with `connections`, connections come from (and stay in) that cache after close()
        # asked before every step and every second while a command runs: a job that must stop
        # (cancelled, or stuck) stops within a second, whatever the command's own timeout
        self._pool = ConnectionPool(
            host_keys, self._policy, self.log, shared=connections, interrupt=interrupt
        )

    def add_secret(self, secret: str) -> None:
        """Mask one more secret in everything logged from now on."""
        self._mask.add(secret)

    def mask(self, text: str) -> str:
        """Return text with every known secret replaced by ***."""
        return self._mask(text)

    def run(
        self,
        machine: SSHTarget,
        command: str,
        *,
        timeout: float | None = None,
        sudo: bool = False,
        check: bool = True,
    ) -> CommandResult:
        """Run a shell command; raise CommandFailed on non-zero exit when check is set."""
        timeout = self._default_timeout if timeout is None else timeout
        if timeout <= 0:
            raise ValueError("timeout must be positive")
        self._pool.check(machine)
        self.log(machine.name, f"$ {'sudo ' if sudo else ''}{command}")
        # the remote `timeout` kills the whole process group, so nothing outlives a timeout;
        # stdin is /dev/null (like `ssh -n`): a command that reads it ends instead of hanging.
        # Never paramiko's shutdown_write(): its EOF, sent outside the channel's lock, can
        # follow the CLOSE its reader thread sends for a command that already ended, and
        # OpenSSH then drops the whole connection, with every machine a jump host carries.
        remote = (
            f"timeout --kill-after={_KILL_AFTER_SECONDS} {timeout:g} "
            f"sh -c {shlex.quote(command)} < /dev/null"
        )
        if sudo:
            remote = f"sudo -n -- {remote}"
        started = time.monotonic()
        channel = self._open_session(machine)
        try:
            channel.exec_command(remote)
            result = self._collect(machine, channel, command, started, timeout)
        finally:
            channel.close()
        self.log(machine.name, f"-> exit {result.exit_code} in {result.duration:.2f} s")
        if result.exit_code in _TIMEOUT_EXIT_CODES and result.duration >= timeout:
            raise CommandTimeout(machine.name, self._mask(command), timeout)
        if check and not result.ok:
            raise CommandFailed(machine.name, self._mask(command), _masked(result, self._mask))
        return result

    def put_file(
        self, machine: SSHTarget, source: Path | str | bytes, remote_path: str, mode: int = 0o644
    ) -> Transfer:
        """Upload a local file or bytes over SFTP; the remote file appears atomically."""
        remote = PurePosixPath(remote_path)
        partial = str(remote.with_name(f".{remote.name}.{token_source.token_hex(6)}.part"))
        label = f"{len(source)} bytes" if isinstance(source, bytes) else str(source)
        self._pool.check(machine)
        self.log(machine.name, f"put {label} -> {remote_path} (mode {mode:04o})")
        digest, size = hashlib.sha256(), 0
        connection = self._pool.get(machine)
        with self._pool.sftp_lock(machine):
            sftp = connection.sftp()
            try:
                with sftp.open(partial, "wb") as remote_file:
                    remote_file.set_pipelined(True)
                    for chunk in _chunks(source):
                        remote_file.write(chunk)
                        digest.update(chunk)
                        size += len(chunk)
                sftp.chmod(partial, mode)
                sftp.posix_rename(partial, remote_path)
            except (OSError, paramiko.SSHException) as exc:
                _remove_quietly(sftp, partial)
                raise SSHError(f"{machine.name}: upload to {remote_path} failed: {exc}") from exc
        return Transfer(size=size, sha256=digest.hexdigest())

    def get_file(self, machine: SSHTarget, remote_path: str, local_path: Path | str) -> Transfer:
        """Download a remote file over SFTP in chunks, replacing local_path when complete."""
        local = Path(local_path)
        partial = local.with_name(f".{local.name}.{token_source.token_hex(6)}.part")
        self._pool.check(machine)
        self.log(machine.name, f"get {remote_path} -> {local}")
        digest, size = hashlib.sha256(), 0
        connection = self._pool.get(machine)
        with self._pool.sftp_lock(machine):
            sftp = connection.sftp()
            try:
                with sftp.open(remote_path, "rb") as remote_file, partial.open("wb") as out:
                    total = remote_file.stat().st_size or 0
                    # pipelined reads one window at a time: fast on high-latency links, and
                    # memory stays at a window (prefetch() keeps whatever arrives, unbounded)
                    for start in range(0, total, _WINDOW):
                        stop = min(start + _WINDOW, total)
                        spans = [(at, min(_CHUNK, stop - at)) for at in range(start, stop, _CHUNK)]
                        for chunk in remote_file.readv(spans):
                            out.write(chunk)
                            digest.update(chunk)
                            size += len(chunk)
                os.replace(partial, local)
            except (OSError, paramiko.SSHException) as exc:
                partial.unlink(missing_ok=True)
                raise SSHError(f"{machine.name}: download of {remote_path} failed: {exc}") from exc
        return Transfer(size=size, sha256=digest.hexdigest())

    def run_parallel(
        self,
        machines: Sequence[SSHTarget],
        task: Callable[[SSHTarget], T],
        *,
        raise_on_error: bool = True,
    ) -> dict[str, T | Exception]:
        """Call task(machine) for every machine at once; map each name to its result or error."""
        names = [machine.name for machine in machines]
        if len(set(names)) != len(names):
            raise ValueError(f"machine names must be unique: {names}")
        if not machines:
            return {}
        with ThreadPoolExecutor(
            max_workers=min(len(machines), self._max_parallel), thread_name_prefix="ssh"
        ) as pool:
            futures = {machine.name: pool.submit(task, machine) for machine in machines}
        outcomes: dict[str, T | Exception] = {}
        for name, future in futures.items():
            error = future.exception()
            if error is None:
                outcomes[name] = future.result()
            elif isinstance(error, Exception):
                outcomes[name] = error
            else:
                raise error  # KeyboardInterrupt and friends are not a machine's failure
        if raise_on_error and any(isinstance(value, Exception) for value in outcomes.values()):
            raise GroupError(outcomes)
        return outcomes

    def close(self) -> None:
        """Close every open connection."""
        self._pool.close_all()

    def __enter__(self) -> SSHExecutor:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()

    def log(self, machine_name: str, line: str) -> None:
        """Send one line about a machine to the log sink, secrets masked."""
        self._sink(machine_name, self._mask(line))

    def _open_session(self, machine: SSHTarget) -> paramiko.Channel:
        # a machine that stopped answering must not hold a channel open for paramiko's hour
        timeout = self._policy.attempt_timeout
        try:
            return _session(self._pool.get(machine), timeout)
        except (OSError, EOFError, paramiko.SSHException) as exc:
            # a cached connection whose machine rebooted or went silent: reconnect once
            self.log(machine.name, f"connection lost ({exc or type(exc).__name__}), reconnecting")
            self._pool.discard(machine)
            return _session(self._pool.get(machine), timeout)

    def _collect(
        self,
        machine: SSHTarget,
        channel: paramiko.Channel,
        command: str,
        started: float,
        timeout: float,
    ) -> CommandResult:
        deadline = started + timeout + _CLIENT_GRACE_SECONDS
        stdout = LineStream(lambda line: self.log(machine.name, line))
        stderr = LineStream(lambda line: self.log(machine.name, f"! {line}"))
        while not channel.eof_received:
            if channel.closed:
                if channel.exit_status == -1:
                    # closed with neither an end of output nor a status: the connection (or
                    # its jump host's) broke, and waiting to the deadline would change nothing
                    raise ConnectionLost(
                        f"{machine.name}: connection lost while running: {self._mask(command)}"
                    )
                break
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise CommandTimeout(machine.name, self._mask(command), timeout)
            # stopping leaves the remote command to its `timeout`, which ends it at the deadline
            self._pool.check(machine)
            select.select([channel], [], [], min(remaining, _INTERRUPT_POLL_SECONDS))
            while channel.recv_ready():
                stdout.feed(channel.recv(_CHUNK))
            while channel.recv_stderr_ready():
                stderr.feed(channel.recv_stderr(_CHUNK))
        while channel.recv_ready():
            stdout.feed(channel.recv(_CHUNK))
        while channel.recv_stderr_ready():
            stderr.feed(channel.recv_stderr(_CHUNK))
        stdout.close()
        stderr.close()
        if not channel.status_event.wait(max(deadline - time.monotonic(), 0.0)):
            raise CommandTimeout(machine.name, self._mask(command), timeout)
        return CommandResult(
            stdout=stdout.text,
            stderr=stderr.text,
            exit_code=channel.recv_exit_status(),
            duration=time.monotonic() - started,
        )


def _session(connection: fabric.Connection, timeout: float) -> paramiko.Channel:
    transport = connection.client.get_transport()
    if transport is None:
        raise paramiko.SSHException("connection has no transport")
    return transport.open_session(timeout=timeout)


def _chunks(source: Path | str | bytes) -> Iterable[bytes]:
    if isinstance(source, bytes):
        for offset in range(0, len(source), _CHUNK):
            yield source[offset : offset + _CHUNK]
        return
    with Path(source).open("rb") as local_file:
        while chunk := local_file.read(_CHUNK):
            yield chunk


def _remove_quietly(sftp: paramiko.SFTPClient, path: str) -> None:
    try:
        sftp.remove(path)
    except OSError:
        pass  # the partial file was never created; the original error is what matters


def _masked(result: CommandResult, mask: SecretMasker) -> CommandResult:
    return CommandResult(
        stdout=mask(result.stdout),
        stderr=mask(result.stderr),
        exit_code=result.exit_code,
        duration=result.duration,
    )
