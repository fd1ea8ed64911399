"""A process's connection cache against a real sshd: reuse, replacement, bounds, forks."""

from __future__ import annotations

import os
import signal
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from cryptography.hazmat.primitives import serialization

from provisioners.remote.ssh import (
    ConnectionCache,
    ConnectPolicy,
    HostKeyMismatch,
    HostKeys,
    SSHExecutor,
    SSHTarget,
)

from .sshd_server import SshServer, make_key_pair, wait_until

POLICY = ConnectPolicy(deadline=15.0, attempt_timeout=5.0, first_delay=0.05)


@pytest.fixture
def cache() -> Iterator[ConnectionCache]:
    """Return a cache of its own; its connections close before sshd stops."""
    made = ConnectionCache()
    yield made
    made.clear()


def executor_with(cache: ConnectionCache, host_keys: HostKeys | None = None) -> SSHExecutor:
    """Return an executor drawing its connections from `cache`, as each beat makes one."""
    return SSHExecutor(host_keys or HostKeys(), connect_policy=POLICY, connections=cache)


def logins(server: SshServer) -> int:
    """Return how many connections sshd has accepted (counted on the server's side)."""
    return (server.workdir / "sshd.log").read_text().count("Accepted publickey")


def sessions(server: SshServer) -> list[int]:
    """Return the PIDs of the per-connection processes of our sshd."""
    assert server.process is not None
    pid = server.process.pid
    return [int(p) for p in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]


def test_a_connection_is_reused_across_executors_and_closed_only_by_the_cache(
    cache: ConnectionCache, sshd: SshServer, make_machine: Callable[..., SSHTarget]
) -> None:
    machine = make_machine(sshd)
    for beat in range(3):
        with executor_with(cache) as executor:
            assert executor.run(machine, f"echo {beat}").stdout == f"{beat}\n"
    assert logins(sshd) == 1
    assert (cache.stats().opened, cache.stats().reused, cache.stats().size) == (1, 2, 1)
    # another machine behind the same address (a new constellation, say) gets its own
    with executor_with(cache) as executor:
        executor.run(make_machine(sshd, name="another/sim"), "true")
        executor.run(machine, "true")
    assert logins(sshd) == 2 and cache.stats().size == 2


def test_a_dead_connection_is_replaced(
    cache: ConnectionCache, sshd: SshServer, make_machine: Callable[..., SSHTarget]
) -> None:
    machine = make_machine(sshd)
    with executor_with(cache) as executor:
        executor.run(machine, "true")
    [session] = sessions(sshd)
    os.killpg(session, signal.SIGKILL)  # the machine's side of the connection dies
    wait_until(lambda: session not in sessions(sshd), 10, "the session to end")
    with executor_with(cache) as executor:
        assert executor.run(machine, "echo again").stdout == "again\n"
    assert logins(sshd) == 2 and cache.stats().opened == 2 and cache.stats().size == 1


def test_a_changed_host_key_is_not_trusted_through_a_kept_connection(
    cache: ConnectionCache, sshd: SshServer, make_machine: Callable[..., SSHTarget]
) -> None:
    machine = make_machine(sshd)
    with executor_with(cache) as executor:
        executor.run(machine, "true")
    pinned_elsewhere = HostKeys(lookup=lambda name: make_key_pair_line())
    with executor_with(cache, pinned_elsewhere) as executor, pytest.raises(HostKeyMismatch):
        executor.run(machine, "true")
    assert cache.stats().size == 0


def make_key_pair_line() -> str:
    """Return the "type base64" of a host key no sshd here presents."""
    return " ".join(make_key_pair(serialization.PrivateFormat.OpenSSH).public_line.split()[:2])


def test_the_cache_is_bounded_and_forgets_terminated_machines(
    sshd_factory: Callable[..., SshServer], make_machine: Callable[..., SSHTarget]
) -> None:
    cache = ConnectionCache(max_size=2)
    servers = [sshd_factory() for _ in range(3)]
    machines = [make_machine(s, name=f"c{n}/sim") for n, s in enumerate(servers)]
    try:
        with executor_with(cache) as executor:
            for machine in machines:
                executor.run(machine, "true")
        assert cache.names() == ["c1/sim", "c2/sim"] and cache.stats().evicted == 1
        wait_until(lambda: not sessions(servers[0]), 10, "the oldest connection to close")
        assert cache.evict_where(lambda name: name.startswith("c1/")) == 1
        assert cache.names() == ["c2/sim"]
    finally:
        cache.clear()


def test_a_forked_child_never_uses_its_parents_connections(
    cache: ConnectionCache, sshd: SshServer, make_machine: Callable[..., SSHTarget]
) -> None:
    machine = make_machine(sshd)
    with executor_with(cache) as executor:
        executor.run(machine, "true")
    child = os.fork()
    if child == 0:  # a Celery prefork worker process, say
        ok = cache.stats().size == 0
        try:
            with executor_with(cache) as executor:
                ok = ok and executor.run(machine, "echo child").stdout == "child\n"
            ok = ok and cache.stats().opened == 1
            cache.clear()
        finally:
            os._exit(0 if ok else 1)
    _, status = os.waitpid(child, 0)
    assert os.waitstatus_to_exitcode(status) == 0
    with executor_with(cache) as executor:
        assert executor.run(machine, "echo parent").stdout == "parent\n"
    assert cache.stats().opened == 1 and logins(sshd) == 2
