"""OpenSSH's client for bulk bytes: pinned host keys, routes, resumption, no key left behind."""

from __future__ import annotations

import hashlib
import os
import signal
import stat
import tempfile
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from provisioners.remote.ssh import (
    HostKeyMismatch,
    HostKeys,
    SSHError,
    SSHExecutor,
    SSHTarget,
    fingerprint,
)
from provisioners.remote.ssh.openssh import OpenSSH

from .sshd_server import KeyPair, LogRecorder, SshServer

pytestmark = pytest.mark.skipif(not OpenSSH.available(), reason="needs OpenSSH's ssh client")


@pytest.fixture
def private_tmp(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Point the temporary folder at one the test watches: key files may appear only there."""
    folder = tmp_path / "tmp"
    folder.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(folder))
    return folder


@pytest.fixture
def remote_file(tmp_path: Path) -> Path:
    """Write 24 MiB of random bytes for the "machine" (sshd on 127.0.0.1) to serve."""
    path = tmp_path / "remote" / "state.msgpack"
    path.parent.mkdir()
    with path.open("wb") as handle:
        for _ in range(24):
            handle.write(os.urandom(1 << 20))
    return path


def _pinned(executor: SSHExecutor, machine: SSHTarget) -> None:
    executor.run(machine, "true")  # first contact records the host key, as a launch does


def _ssh_children() -> list[int]:
    own = Path(f"/proc/self/task/{threading.get_native_id()}/children").read_text().split()
    return [int(pid) for pid in own if _command_name(pid) == "ssh"]


def _command_name(pid: str) -> str:
    try:
        return Path(f"/proc/{pid}/comm").read_text().strip()
    except FileNotFoundError:  # it exited (and was reaped) since the list was read
        return ""


def test_a_download_through_a_jump_machine_arrives_whole_and_leaves_no_key(
    sshd_factory: Callable[..., SshServer],
    make_machine: Callable[..., SSHTarget],
    executor: SSHExecutor,
    host_keys: HostKeys,
    client_key: KeyPair,
    remote_file: Path,
    private_tmp: Path,
    tmp_path: Path,
) -> None:
    jump = make_machine(sshd_factory(), name="router")
    # the machine behind it is reached through the jump machine (ssh -W), as a cloud's LAN
    behind = sshd_factory()
    sim = make_machine(behind, name="sim", jump=jump)
    _pinned(executor, sim)
    log = LogRecorder()
    seen: list[tuple[int, int]] = []

    def watch(done: int) -> None:
        if not seen:  # while bytes flow: the key is on disk, private, and only there
            (folder,) = private_tmp.iterdir()
            key = next(folder.glob("key*"))
            seen.append((stat.S_IMODE(folder.stat().st_mode), stat.S_IMODE(key.stat().st_mode)))

    local = tmp_path / "copy" / "state.msgpack"
    local.parent.mkdir()
    transfer = OpenSSH(host_keys, log=log).download(sim, str(remote_file), local, progress=watch)

    expected = hashlib.sha256(remote_file.read_bytes()).hexdigest()
    assert (transfer.size, transfer.sha256, transfer.resumed_from) == (24 << 20, expected, 0)
    assert hashlib.sha256(local.read_bytes()).hexdigest() == expected
    assert seen == [(0o700, 0o600)]
    assert list(private_tmp.iterdir()) == []  # the key files went with the folder
    assert not list(local.parent.glob(".*.part"))
    secret_lines = client_key.private_pem.strip().splitlines()[1:-1]
    assert log.lines and not any(s in line for _, line in log.lines for s in secret_lines)


def test_a_proxy_command_route_is_followed(
    sshd: SshServer,
    make_machine: Callable[..., SSHTarget],
    executor: SSHExecutor,
    host_keys: HostKeys,
    remote_file: Path,
    tmp_path: Path,
) -> None:
    # a literal % in the proxy's argv must reach it unexpanded
    proxy = ["sh", "-c", 'test "$1" = 100% && exec socat STDIO TCP:127.0.0.1:$0', str(sshd.port)]
    sim = make_machine(sshd, proxy_command=[*proxy, "100%"])
    _pinned(executor, sim)
    transfer = OpenSSH(host_keys).download(sim, str(remote_file), tmp_path / "copy")
    assert transfer.sha256 == hashlib.sha256(remote_file.read_bytes()).hexdigest()


def test_a_changed_host_key_is_refused_and_nothing_is_complete(
    sshd_factory: Callable[..., SshServer],
    make_machine: Callable[..., SSHTarget],
    executor: SSHExecutor,
    host_keys: HostKeys,
    remote_file: Path,
    private_tmp: Path,
    tmp_path: Path,
) -> None:
    server = sshd_factory()
    sim = make_machine(server)
    _pinned(executor, sim)
    executor.close()
    server.stop()
    rebuilt = sshd_factory(port=server.port)  # another machine answers on the same address
    local = tmp_path / "state.msgpack"
    with pytest.raises(HostKeyMismatch) as refused:
        OpenSSH(host_keys).download(sim, str(remote_file), local)
    assert "host key of machine 'sim' changed" in str(refused.value)
    assert refused.value.presented == fingerprint(rebuilt.host_key_line).split()[1]
    assert not local.exists() and list(tmp_path.glob(".*.part")) == []
    assert list(private_tmp.iterdir()) == []


def test_an_interrupted_copy_resumes_from_its_offset(
    sshd: SshServer,
    make_machine: Callable[..., SSHTarget],
    executor: SSHExecutor,
    host_keys: HostKeys,
    remote_file: Path,
    tmp_path: Path,
) -> None:
    sim = make_machine(sshd)
    _pinned(executor, sim)
    local = tmp_path / "state.msgpack"
    killed: list[int] = []

    def kill_midway(done: int) -> None:
        if done >= 4 << 20 and not killed:
            (pid,) = _ssh_children()  # the ssh process carrying the bytes
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)

    with pytest.raises(SSHError, match="killed by signal 9"):
        OpenSSH(host_keys).download(sim, str(remote_file), local, progress=kill_midway)
    partial = tmp_path / ".state.msgpack.part"
    copied = partial.stat().st_size
    assert not local.exists() and (4 << 20) <= copied < (24 << 20)
    whole = remote_file.read_bytes()
    assert partial.read_bytes() == whole[:copied]

    transfer = OpenSSH(host_keys).download(sim, str(remote_file), local)
    assert transfer.resumed_from == copied and transfer.size == len(whole)
    assert transfer.sha256 == hashlib.sha256(whole).hexdigest()
    assert local.read_bytes() == whole and not partial.exists()


@pytest.fixture(autouse=True)
def _no_leftover_children() -> Iterator[None]:
    yield
    assert _ssh_children() == []  # every ssh the transport started was reaped
