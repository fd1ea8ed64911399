"""Uploading and downloading files over SFTP."""

from __future__ import annotations

import hashlib
import os
from collections.abc import Callable
from pathlib import Path

import pytest

from provisioners.remote.ssh import SSHError, SSHExecutor, SSHTarget

from .sshd_server import SshServer


def test_put_bytes_then_get_them_back_with_matching_checksums(
    executor: SSHExecutor, sshd: SshServer, make_machine: Callable[..., SSHTarget], tmp_path: Path
) -> None:
    machine = make_machine(sshd)
    payload = os.urandom(3 * 1024 * 1024 + 17)  # several SFTP chunks and an odd tail
    remote = tmp_path / "remote" / "payload.bin"
    remote.parent.mkdir()
    uploaded = executor.put_file(machine, payload, str(remote), mode=0o640)
    assert uploaded.sha256 == hashlib.sha256(payload).hexdigest()
    assert uploaded.size == len(payload)
    assert remote.stat().st_mode & 0o777 == 0o640
    remote_sum = executor.run(machine, f"sha256sum {remote}").stdout.split()[0]
    assert remote_sum == uploaded.sha256

    local = tmp_path / "local" / "copy.bin"
    local.parent.mkdir()
    downloaded = executor.get_file(machine, str(remote), local)
    assert downloaded == uploaded
    assert hashlib.sha256(local.read_bytes()).hexdigest() == uploaded.sha256
    assert sorted(p.name for p in remote.parent.iterdir()) == ["payload.bin"]
    assert sorted(p.name for p in local.parent.iterdir()) == ["copy.bin"]


def test_put_local_file_replaces_the_remote_file(
    executor: SSHExecutor, sshd: SshServer, make_machine: Callable[..., SSHTarget], tmp_path: Path
) -> None:
    machine = make_machine(sshd)
    source = tmp_path / "source.conf"
    source.write_text("new contents\n")
    remote = tmp_path / "target.conf"
    remote.write_text("old contents\n")
    executor.put_file(machine, source, str(remote), mode=0o600)
    assert remote.read_text() == "new contents\n"
    assert remote.stat().st_mode & 0o777 == 0o600


def test_failed_transfers_raise_and_leave_no_partial_files(
    executor: SSHExecutor, sshd: SshServer, make_machine: Callable[..., SSHTarget], tmp_path: Path
) -> None:
    machine = make_machine(sshd)
    with pytest.raises(SSHError, match=r"download of .*missing\.bin failed"):
        executor.get_file(machine, str(tmp_path / "missing.bin"), tmp_path / "copy.bin")
    with pytest.raises(SSHError, match=r"upload to .*no-such-dir/x failed"):
        executor.put_file(machine, b"x", str(tmp_path / "no-such-dir" / "x"))
    assert list(tmp_path.iterdir()) == [tmp_path / "sshd-0"]
