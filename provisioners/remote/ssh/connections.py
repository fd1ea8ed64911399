"""Open, reuse and close SSH connections, retrying while machines boot."""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import fabric
import paramiko

from provisioners.remote.ssh.errors import ConnectError, Interrupted
from provisioners.remote.ssh.hostkeys import HostKeyStore, TrustOnFirstUse
from provisioners.remote.ssh.proxy import ArgvProxyCommand
from provisioners.remote.ssh.target import SSHTarget, load_private_key

if TYPE_CHECKING:
    from provisioners.remote.ssh.cache import ConnectionCache

# how long to wait for paramiko's reader thread to stop after a connection is closed
_READER_STOP_SECONDS = 5.0
# the caller's "must I stop?": None to go on, else why it stops (a cancelled job, say)
Interrupt = Callable[[], str | None]
# what a machine that is still booting (or a proxy/jump path not yet ready) looks like
_RETRYABLE = (OSError, EOFError, paramiko.SSHException)


@dataclass(frozen=True)
class ConnectPolicy:
    """How long and how often to try reaching a machine."""

    deadline: float = 120.0  # total seconds spent trying before giving up
    attempt_timeout: float = 10.0  # seconds for one TCP connect / banner / auth
    first_delay: float = 0.25  # seconds before the second attempt
    max_delay: float = 5.0  # the delay doubles up to this

    def __post_init__(self) -> None:
        if min(self.deadline, self.attempt_timeout, self.first_delay, self.max_delay) <= 0:
            raise ValueError("connect policy durations must be positive")


class ConnectionPool:
    """Keep one open connection per machine name; open it on demand with backoff.

    With a `shared` cache the connections are the cache's: they outlive this pool and are
    handed to every pool of the process that reaches the same machine the same way.
    """

    def __init__(
        self,
        host_keys: HostKeyStore,
        policy: ConnectPolicy,
        log: Callable[[str, str], None],
        shared: ConnectionCache | None = None,
        interrupt: Interrupt | None = None,
    ) -> None:
        self._interrupt = interrupt or (lambda: None)
        self._host_keys = host_keys
        self._policy = policy
        self._log = log
        self._shared = shared
        self._connections: dict[str, tuple[SSHTarget, fabric.Connection]] = {}
        self._keys: dict[str, paramiko.PKey] = {}
        self._locks: dict[str, threading.Lock] = {}
        self._sftp_locks: dict[str, threading.Lock] = {}
        self._pool_lock = threading.Lock()

    def machine_lock(self, machine: SSHTarget) -> threading.Lock:
        """Return the lock that serialises connecting to one machine."""
        with self._pool_lock:
            return self._locks.setdefault(machine.name, threading.Lock())

    def sftp_lock(self, machine: SSHTarget) -> threading.Lock:
        """Return the lock that serialises transfers on one machine's SFTP session."""
        if self._shared is not None:
            return self._shared.sftp_lock(machine)
        with self._pool_lock:
            return self._sftp_locks.setdefault(machine.name, threading.Lock())

    def get(self, machine: SSHTarget) -> fabric.Connection:
        """Return an open connection to the machine, connecting (with retries) if needed."""
        if self._shared is not None:
            return self._shared.get(
                machine, self._host_keys, lambda: self._connect_with_retries(machine)
            )
        with self.machine_lock(machine):
            cached = self._connections.get(machine.name)
            if cached is not None:
                cached_machine, connection = cached
                if cached_machine == machine and connection.is_connected:
                    return connection
                self._drop(machine.name)
            connection = self._connect_with_retries(machine)
            self._connections[machine.name] = (machine, connection)
            return connection

    def discard(self, machine: SSHTarget) -> None:
        """Close a machine's connection, e.g. after its transport broke."""
        if self._shared is not None:
            self._shared.evict(machine)
            return
        with self.machine_lock(machine):
            self._drop(machine.name)

    def close_all(self) -> None:
        """Close every connection this pool owns (those through a jump host first)."""
        with self._pool_lock:
            names = list(self._connections)
        # a jump host's connection carries others: close the carried ones first
        names.sort(key=lambda name: jump_depth(self._connections[name][0]), reverse=True)
        for name in names:
            with self._locks[name]:
                self._drop(name)

    def _drop(self, name: str) -> None:
        cached = self._connections.pop(name, None)
        if cached is not None:
            close_connection(cached[1])

    def _connect_with_retries(self, machine: SSHTarget) -> fabric.Connection:
        deadline = time.monotonic() + self._policy.deadline
        delay = self._policy.first_delay
        attempt = 0
        while True:
            attempt += 1
            self.check(machine)
            try:
                connection = self._connect_once(machine)
            except _RETRYABLE as exc:
                reason = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
                self._log(machine.name, f"connect attempt {attempt} failed: {reason}")
                if time.monotonic() + delay > deadline:
                    raise ConnectError(
                        f"machine {machine.name!r} ({machine.address}) not reachable after "
                        f"{attempt} attempts in {self._policy.deadline:g} s: {reason}"
                    ) from exc
                # backoff between attempts of a booting machine, not a wait in a test
                time.sleep(delay)
                delay = min(delay * 2, self._policy.max_delay)
                continue
            if attempt > 1:
                self._log(machine.name, f"connected on attempt {attempt}")
            return connection

    def check(self, machine: SSHTarget) -> None:
        """Raise Interrupted when the caller said stop."""
        reason = self._interrupt()
        if reason is not None:
            raise Interrupted(f"{machine.name}: stopped: {reason}")

    def _connect_once(self, machine: SSHTarget) -> fabric.Connection:
        sock = self._open_path(machine)
        connection = fabric.Connection(
            machine.host,
            user=machine.user,
            port=machine.port,
            # an explicit empty ssh config: ~/.ssh/config must not change where we connect
            config=fabric.Config(ssh_config=paramiko.SSHConfig(), lazy=True),
            connect_kwargs={
                "pkey": self._key(machine),
                "sock": sock,
                "allow_agent": False,
                "look_for_keys": False,
                "timeout": self._policy.attempt_timeout,
                "banner_timeout": self._policy.attempt_timeout,
                "auth_timeout": self._policy.attempt_timeout,
            },
        )
        policy = TrustOnFirstUse(
            self._host_keys, machine.name, lambda line: self._log(machine.name, line)
        )
        connection.client.set_missing_host_key_policy(policy)
        try:
            connection.open()
        except BaseException:
            # fabric's close() skips a transport that died mid-handshake; its socket must go too
            transport = connection.client.get_transport()
            connection.client.close()
            if transport is not None:
                transport.join(_READER_STOP_SECONDS)
            if sock is not None:
                sock.close()
                if isinstance(sock, ArgvProxyCommand):
                    sock.release()
            raise
        transport = connection.client.get_transport()
        if transport is not None:
            # notice a machine that vanished instead of hanging on a dead TCP connection
            transport.set_keepalive(15)
            if isinstance(transport.sock, socket.socket):
                # without it Nagle + delayed ACK add ~40 ms to every channel open
                transport.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        return connection

    def _open_path(self, machine: SSHTarget) -> ArgvProxyCommand | paramiko.Channel | None:
        if machine.proxy_command is not None:
            return ArgvProxyCommand(machine.proxy_command)
        if machine.jump is not None:
            jump_transport = self.get(machine.jump).transport
            if jump_transport is None:
                raise paramiko.SSHException(f"jump machine {machine.jump.name!r} has no transport")
            return jump_transport.open_channel(
                "direct-tcpip",
                dest_addr=(machine.host, machine.port),
                src_addr=("", 0),
                timeout=self._policy.attempt_timeout,
            )
        return None

    def _key(self, machine: SSHTarget) -> paramiko.PKey:
        key = self._keys.get(machine.private_key)
        if key is None:
            key = load_private_key(machine.name, machine.private_key)
            self._keys[machine.private_key] = key
        return key


def close_connection(connection: fabric.Connection) -> None:
    """Close a connection, wait for its reader thread, and release its proxy's pipes."""
    transport = connection.client.get_transport()
    connection.close()
    if transport is not None:
        transport.join(_READER_STOP_SECONDS)  # the reader thread must be done with the proxy
        if isinstance(transport.sock, ArgvProxyCommand):
            transport.sock.release()


def jump_depth(machine: SSHTarget) -> int:
    """Return how many jump machines stand between the controller and this one."""
    depth = 0
    while machine.jump is not None:
        machine, depth = machine.jump, depth + 1
    return depth
