"""Helpers for the local provider tests: SSH keys and sessions, leftover sweeping."""

import os
import shlex
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import paramiko
import pytest
from libcloud.compute.base import Node, NodeAuthSSHKey

from provisioners.providers.local.driver import LocalNodeDriver
from provisioners.providers.local.network import LocalNetwork

IS_ROOT = os.geteuid() == 0
needs_root = pytest.mark.skipif(not IS_ROOT, reason="local hosts need root")


@dataclass(frozen=True)
class SshKey:
    """An ed25519 key pair generated for the test session."""

    private: paramiko.PKey
    public_line: str

    @property
    def auth(self) -> NodeAuthSSHKey:
        """Return the libcloud auth object carrying the public key."""
        return NodeAuthSSHKey(self.public_line)


class _DeferredProxyCommand(paramiko.ProxyCommand):
    """A ProxyCommand that outlives paramiko's close until its reader thread has stopped."""

    def close(self) -> None:
        # paramiko closes the socket without waiting for its reader thread: killing the
        # proxy then makes that thread log broken pipes, and closing the pipes would let it
        # read from whatever file reuses their descriptors (another session's stream).
        pass

    def shutdown(self) -> None:
        """Stop and reap the proxy process and close its pipes."""
        if self.process.returncode is None:
            self.process.terminate()
            self.process.wait(timeout=10)
        for pipe in (self.process.stdin, self.process.stdout, self.process.stderr):
            if pipe is not None:
                pipe.close()


class _RecordingPolicy(paramiko.MissingHostKeyPolicy):
    """Accept the first host key of a fresh host and remember it for assertions."""

    def __init__(self) -> None:
        self.host_key: paramiko.PKey | None = None

    def missing_host_key(
        self, client: paramiko.SSHClient, hostname: str, key: paramiko.PKey
    ) -> None:
        self.host_key = key


@dataclass
class HostShell:
    """An SSH session to one node, opened through the node's ssh_proxy_command."""

    client: paramiko.SSHClient
    proxy: _DeferredProxyCommand
    host_key: paramiko.PKey
    closed: bool = field(default=False)

    def run(self, command: str, timeout: float = 30.0) -> tuple[int, str, str]:
        """Run a shell command on the host; return (exit status, stdout, stderr)."""
        _stdin, stdout, stderr = self.client.exec_command(command, timeout=timeout)
        if not stdout.channel.status_event.wait(timeout):
            raise TimeoutError(f"{command!r} did not finish in {timeout} s")
        status = stdout.channel.recv_exit_status()
        return status, stdout.read().decode(), stderr.read().decode()

    def check(self, command: str, timeout: float = 30.0) -> str:
        """Run a command that must succeed and return its stdout."""
        status, out, err = self.run(command, timeout)
        assert status == 0, f"{command!r} exited {status}: {err}"
        return out

    def close(self) -> None:
        """Close the SSH connection and reap the proxy process."""
        if not self.closed:
            _close_connection(self.client, self.proxy)
            self.closed = True


def _close_connection(client: paramiko.SSHClient, proxy: _DeferredProxyCommand) -> None:
    """Close the client, wait for its reader thread, then stop and reap the proxy."""
    transport = client.get_transport()
    client.close()
    if transport is not None:
        transport.join(timeout=10)
        assert not transport.is_alive(), "paramiko transport thread did not stop"
    proxy.shutdown()


def open_shell(node: Node, key: SshKey) -> HostShell:
    """Open an SSH session as root to node through its ssh_proxy_command."""
    proxy = _DeferredProxyCommand(shlex.join(node.extra["ssh_proxy_command"]))
    client = paramiko.SSHClient()
    policy = _RecordingPolicy()
    client.set_missing_host_key_policy(policy)
    try:
        client.connect(
            hostname=node.name,
            username="root",
            pkey=key.private,
            sock=proxy,
            look_for_keys=False,
            allow_agent=False,
            timeout=20,
            banner_timeout=20,
            auth_timeout=20,
        )
    except BaseException:
        _close_connection(client, proxy)
        raise
    assert policy.host_key is not None
    return HostShell(client=client, proxy=proxy, host_key=policy.host_key)


def create_host(
    driver: LocalNodeDriver, name: str, network: LocalNetwork, key: SshKey, **options: Any
) -> Node:
    """Create a host on network that accepts key, with create_node's ex_ options."""
    return driver.create_node(name, None, None, auth=key.auth, ex_network=network, **options)


def destroy_everything(state_dir: Path, prefix: str) -> list[str]:
    """Destroy every node and network of prefix; report whatever had leaked past its records."""
    leftovers = LocalNodeDriver(state_dir=str(state_dir), prefix=prefix).ex_sweep()
    leftovers += [f"mount {point}" for point in mounts_under(state_dir)]
    leftovers += [f"file {path}" for path in sorted(state_dir.rglob("*")) if path.name != ".lock"]
    return leftovers


def mounts_under(directory: Path) -> list[str]:
    """Return the mount points at or below directory, deepest first."""
    points = [line.split()[1] for line in Path("/proc/mounts").read_text().splitlines()]
    inside = [point for point in points if point.startswith(str(directory))]
    return sorted(inside, key=len, reverse=True)
