"""Host key trust on first use, and reaching machines through a proxy command or a jump host."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from provisioners.remote.ssh import (
    ConnectError,
    ConnectPolicy,
    HostKeyMismatch,
    HostKeys,
    SSHExecutor,
    SSHTarget,
    fingerprint,
)

from .sshd_server import LogRecorder, SshServer


def test_host_key_is_recorded_at_first_contact_and_checked_afterwards(
    sshd_factory: Callable[..., SshServer],
    make_machine: Callable[..., SSHTarget],
    host_keys: HostKeys,
    log: LogRecorder,
) -> None:
    server = sshd_factory()
    machine = make_machine(server, name="router")
    with SSHExecutor(host_keys, log_sink=log) as ssh:
        ssh.run(machine, "true")
    assert host_keys.get("router") == server.host_key_line
    assert f"recorded host key {fingerprint(server.host_key_line)}" in log.text("router")

    with SSHExecutor(host_keys) as ssh:  # same key: a later connection is accepted silently
        assert ssh.run(machine, "echo again").stdout == "again\n"

    # the "machine" is rebuilt with a new host key on the same address
    server.stop()
    rebuilt = sshd_factory(port=server.port)
    with SSHExecutor(host_keys) as ssh, pytest.raises(HostKeyMismatch) as mismatch:
        ssh.run(machine, "true")
    assert mismatch.value.machine_name == "router"
    assert mismatch.value.expected == fingerprint(server.host_key_line)
    assert mismatch.value.presented == fingerprint(rebuilt.host_key_line)
    assert "host key of machine 'router' changed" in str(mismatch.value)
    assert host_keys.get("router") == server.host_key_line  # never silently replaced


def test_host_keys_are_kept_per_machine_name(
    sshd_factory: Callable[..., SshServer],
    make_machine: Callable[..., SSHTarget],
    host_keys: HostKeys,
) -> None:
    first, second = sshd_factory(), sshd_factory()
    with SSHExecutor(host_keys) as ssh:
        ssh.run(make_machine(first, name="sim"), "true")
        ssh.run(make_machine(second, name="fc1"), "true")
    assert host_keys.get("sim") == first.host_key_line
    assert host_keys.get("fc1") == second.host_key_line


def test_proxy_command_carries_the_connection(
    executor: SSHExecutor, sshd: SshServer, make_machine: Callable[..., SSHTarget]
) -> None:
    # the address alone leads nowhere: only the proxy knows the way, as for a host in a netns
    machine = make_machine(
        sshd,
        name="netns-host",
        host="10.255.255.1",
        port=1,
        proxy_command=["socat", "STDIO", f"TCP:127.0.0.1:{sshd.port}"],
    )
    assert executor.run(machine, "echo through-proxy").stdout == "through-proxy\n"
    assert executor.run(machine, "echo $SSH_CLIENT").stdout.startswith("127.0.0.1 ")


def test_failing_proxy_command_is_retried_then_a_connect_error(
    host_keys: HostKeys, sshd: SshServer, make_machine: Callable[..., SSHTarget]
) -> None:
    machine = make_machine(sshd, name="unreachable", proxy_command=["false"])
    policy = ConnectPolicy(deadline=0.5, attempt_timeout=2.0, first_delay=0.1)
    with SSHExecutor(host_keys, connect_policy=policy) as ssh, pytest.raises(ConnectError) as error:
        ssh.run(machine, "true")
    assert "'unreachable'" in str(error.value)


def test_missing_proxy_program_fails_at_once(
    host_keys: HostKeys, sshd: SshServer, make_machine: Callable[..., SSHTarget]
) -> None:
    machine = make_machine(sshd, name="nshost", proxy_command=["/nonexistent/cloudsim-proxy"])
    patient = ConnectPolicy(deadline=600.0)  # would take ten minutes if it were retried
    with (
        SSHExecutor(host_keys, connect_policy=patient) as ssh,
        pytest.raises(ConnectError) as error,
    ):
        ssh.run(machine, "true")
    assert "proxy command '/nonexistent/cloudsim-proxy' cannot start" in str(error.value)


def test_jump_machine_forwards_to_a_private_machine(
    executor: SSHExecutor,
    sshd_factory: Callable[..., SshServer],
    make_machine: Callable[..., SSHTarget],
    host_keys: HostKeys,
) -> None:
    router_server, sim_server = sshd_factory(), sshd_factory()
    router = make_machine(router_server, name="router")
    sim = make_machine(sim_server, name="sim", jump=router)
    client_port = executor.run(sim, "echo $SSH_CLIENT").stdout.split()[1]
    # the sim's sshd must see a TCP connection made by the router's sshd, not by us
    owner = executor.run(router, f"ss -Htnp state established '( sport = :{client_port} )'").stdout
    assert '"sshd"' in owner and "python" not in owner
    assert host_keys.get("sim") == sim_server.host_key_line
    assert host_keys.get("router") == router_server.host_key_line


def test_machine_rejects_contradictory_paths(make_machine: Callable[..., SSHTarget]) -> None:
    server = SshServer(workdir=Path("/nonexistent"), port=22, client_public_line="")
    router = make_machine(server, name="router")
    with pytest.raises(ValueError, match="not both"):
        make_machine(server, name="sim", jump=router, proxy_command=["socat"])
    with pytest.raises(ValueError, match="own jump"):
        make_machine(server, name="router", jump=router)
    assert "private_key" not in repr(router)
