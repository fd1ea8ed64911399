"""Keep SSH connections open across executors of one process: checked, bounded, fork-safe."""

from __future__ import annotations

import atexit
import hashlib
import os
import threading
import weakref
from collections import OrderedDict
from collections.abc import Callable, Hashable
from dataclasses import dataclass

import fabric

from provisioners.remote.ssh.connections import close_connection, jump_depth
from provisioners.remote.ssh.hostkeys import HostKeyStore
from provisioners.remote.ssh.target import SSHTarget

# how many connections a process keeps by default (about two per live run at season scale)
DEFAULT_MAX_SIZE = 256
# connections a forked child inherited: never used, closed or collected there (see _after_fork)
_FORSAKEN: list[object] = []


@dataclass(frozen=True)
class CacheStats:
    """What a cache did so far: connections opened, handed out again, closed; how many are open."""

    opened: int
    reused: int
    evicted: int
    size: int


def machine_key(machine: SSHTarget) -> Hashable:
    """Return what identifies a connection: the machine's route, login and key (never the key)."""
    proxy = tuple(machine.proxy_command) if machine.proxy_command else None
    return (
        machine.name,
        machine.host,
        machine.user,
        machine.port,
        proxy,
        hashlib.sha256(machine.private_key.encode()).hexdigest(),
        machine_key(machine.jump) if machine.jump is not None else None,
    )


@dataclass
class _Entry:
    machine: SSHTarget
    connection: fabric.Connection
    host_key: str  # "type base64" the machine presented when it was connected


class ConnectionCache:
    """One open connection per machine route, shared by every executor of this process.

    A connection is handed out again while its transport is alive and the machine's
    recorded host key is still the one it presented; otherwise it is closed and a new one
    made. At most `max_size` stay open (the least recently used is closed). Paramiko
    transports cannot cross a fork (their reader thread stays in the parent and both
    processes would write to one socket): a forked child starts with an empty cache and
    leaves what it inherited alone.
    """

    def __init__(self, max_size: int = DEFAULT_MAX_SIZE) -> None:
        if max_size < 1:
            raise ValueError("a connection cache holds at least one connection")
        self.max_size = max_size
        self._reset()
        ref = weakref.ref(self)
        os.register_at_fork(after_in_child=lambda: _call_if_alive(ref, ConnectionCache._after_fork))

    def _reset(self) -> None:
        self._entries: OrderedDict[Hashable, _Entry] = OrderedDict()
        self._locks: dict[Hashable, threading.Lock] = {}
        self._sftp_locks: dict[Hashable, threading.Lock] = {}
        self._lock = threading.Lock()
        self._opened = self._reused = self._evicted = 0

    def get(
        self,
        machine: SSHTarget,
        host_keys: HostKeyStore,
        connect: Callable[[], fabric.Connection],
    ) -> fabric.Connection:
        """Return the machine's open connection, or make one with `connect` and keep it."""
        key = machine_key(machine)
        with self._key_lock(key):
            with self._lock:
                entry = self._entries.get(key)
                if entry is not None:
                    self._entries.move_to_end(key)
            if entry is not None:
                if _alive(entry) and _same_host_key(entry, host_keys.get(machine.name)):
                    with self._lock:
                        self._reused += 1
                    return entry.connection
                self._close(key)
            connection = connect()
            transport = connection.client.get_transport()
            server_key = transport.get_remote_server_key() if transport is not None else None
            presented = f"{server_key.get_name()} {server_key.get_base64()}" if server_key else ""
            with self._lock:
                self._entries[key] = _Entry(machine, connection, presented)
                self._opened += 1
                over = list(self._entries)[: max(len(self._entries) - self.max_size, 0)]
        for old in over:
            self._close(old)
        return connection

    def evict(self, machine: SSHTarget) -> bool:
        """Close the machine's connection (after an error); True if there was one."""
        return self._close(machine_key(machine))

    def evict_where(self, gone: Callable[[str], bool]) -> int:
        """Close the connections of every machine whose name `gone` accepts; return how many."""
        with self._lock:
            found = [
                (jump_depth(entry.machine), key)
                for key, entry in self._entries.items()
                if gone(entry.machine.name)
            ]
        # a jump machine's connection carries others: close the carried ones first
        found.sort(key=lambda depth_key: depth_key[0], reverse=True)
        return sum(self._close(key) for _, key in found)

    def prune(self) -> int:
        """Close the connections whose transport has died; return how many."""
        with self._lock:
            dead = [key for key, entry in self._entries.items() if not _alive(entry)]
        return sum(self._close(key) for key in dead)

    def clear(self) -> None:
        """Close every connection."""
        self.evict_where(lambda name: True)

    def sftp_lock(self, machine: SSHTarget) -> threading.Lock:
        """Return the lock that serialises transfers on one connection's SFTP session."""
        with self._lock:
            return self._sftp_locks.setdefault(machine_key(machine), threading.Lock())

    def names(self) -> list[str]:
        """Return the names of the machines with an open connection."""
        with self._lock:
            return [entry.machine.name for entry in self._entries.values()]

    def stats(self) -> CacheStats:
        """Return the counters and the number of open connections."""
        with self._lock:
            return CacheStats(self._opened, self._reused, self._evicted, len(self._entries))

    def _key_lock(self, key: Hashable) -> threading.Lock:
        with self._lock:
            return self._locks.setdefault(key, threading.Lock())

    def _close(self, key: Hashable) -> bool:
        with self._lock:
            entry = self._entries.pop(key, None)
            if entry is not None:
                self._evicted += 1
        if entry is None:
            return False
        close_connection(entry.connection)
        return True

    def _after_fork(self) -> None:
        # the child must neither use nor close (nor let the garbage collector close) the
        # parent's transports: a channel's __del__ would write into the parent's stream
        _FORSAKEN.append(self._entries)
        self._reset()


def _call_if_alive(
    ref: weakref.ReferenceType[ConnectionCache], method: Callable[[ConnectionCache], None]
) -> None:
    cache = ref()
    if cache is not None:
        method(cache)


def _alive(entry: _Entry) -> bool:
    transport = entry.connection.client.get_transport()
    return transport is not None and transport.is_active() and transport.is_authenticated()


def _same_host_key(entry: _Entry, recorded: str | None) -> bool:
    # a machine rebuilt behind the same route presents another key: connect again and check it
    return recorded is None or recorded.split()[:2] == entry.host_key.split()


_process_cache: ConnectionCache | None = None
_process_lock = threading.Lock()


def process_cache() -> ConnectionCache:
    """Return this process's connection cache, made at first use and closed at exit."""
    global _process_cache
    with _process_lock:
        if _process_cache is None:
            _process_cache = ConnectionCache()
            atexit.register(_process_cache.clear)
        return _process_cache
