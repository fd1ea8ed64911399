"""Collecting a run's logs from a real sshd: bytes and checksums, resumption, a changed host key."""

from __future__ import annotations

import hashlib
import os
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from flask import Flask

from cloudsim.competition import artifacts
from cloudsim.competition.artifacts import BULK_BYTES, LogStore, collect_logs, run_dir
from cloudsim.extensions import db
from cloudsim.models import Run, RunState, Team
from provisioners.remote.ssh import ConnectPolicy, HostKeys, SSHExecutor, SSHTarget
from tests.competition.support import open_task
from tests.provisioners.remote.ssh.conftest import (  # noqa: F401 (fixtures)
    client_key,
    privsep_dir,
    sshd_factory,
)
from tests.provisioners.remote.ssh.sshd_server import KeyPair, LogRecorder, SshServer

STATE_BYTES = BULK_BYTES + (3 << 20)  # big enough to travel over OpenSSH


@pytest.fixture
def runs_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Keep the "machine's" run folders (sshd runs on this host) under the test's folder."""
    folder = tmp_path / "machine-runs"
    monkeypatch.setattr(artifacts, "RUNS_DIR", str(folder))
    return folder


@pytest.fixture
def run(app: Flask, team_a: Team, runs_dir: Path) -> Run:
    """Add a stopping run whose logs are on the machine, the state log a big random file."""
    made = Run(task_id=open_task(team_a.id).id, team_id=team_a.id, state=RunState.STOPPING)
    db.session.add(made)
    db.session.commit()
    folder = Path(run_dir(made.id))
    folder.mkdir(parents=True)
    for log in artifacts.RUN_LOGS:
        if log.machine == "sim" and log.filename != "final.json":  # the simulator died
            (folder / log.filename).write_bytes(f"{log.kind} log\n".encode())
    (folder / "state.msgpack").write_bytes(os.urandom(STATE_BYTES))
    return made


@pytest.fixture
def sim(sshd_factory: Callable[..., SshServer], client_key: KeyPair) -> SSHTarget:  # noqa: F811
    """Return the run's sim: a real sshd on 127.0.0.1."""
    server = sshd_factory()
    return SSHTarget(
        name="sim", host="127.0.0.1", port=server.port, private_key=client_key.private_pem
    )


@pytest.fixture
def host_keys() -> HostKeys:
    """Return the host key store the collection pins keys in."""
    return HostKeys()


@pytest.fixture
def collect(app: Flask, host_keys: HostKeys, tmp_path: Path) -> Iterator[Callable[..., list[str]]]:
    """Return a function that collects a run's logs from the given sim, logging to `lines`."""
    executors: list[SSHExecutor] = []

    def collect_from(run: Run, sim: SSHTarget, lines: list[str]) -> list[str]:
        recorder = LogRecorder()
        executor = SSHExecutor(
            host_keys, log_sink=recorder, connect_policy=ConnectPolicy(deadline=5, first_delay=0.05)
        )
        executors.append(executor)
        store = LogStore(app.config["CLOUDSIM"])
        problems = collect_logs(
            run, executor, {"sim": sim}, store, tmp_path / "staging", lines.append
        )
        executor.close()
        lines.extend(line for _, line in recorder.lines)
        return problems

    yield collect_from
    for executor in executors:
        executor.close()


def test_collected_logs_match_the_machine_byte_for_byte(
    app: Flask, run: Run, sim: SSHTarget, collect: Callable[..., list[str]]
) -> None:
    lines: list[str] = []
    assert collect(run, sim, lines) == []
    store = LogStore(app.config["CLOUDSIM"])
    folder = Path(run_dir(run.id))
    stored = {a.filename: a for a in run.artifacts}
    assert set(stored) == {p.name for p in folder.iterdir()}  # final.json: optional, absent
    for name, artifact in stored.items():
        data = (folder / name).read_bytes()
        assert artifact.sha256 == hashlib.sha256(data).hexdigest() and artifact.size == len(data)
        assert b"".join(store.stream(artifact.location)) == data
    assert any("state.msgpack" in line and "with OpenSSH" in line for line in lines)
    assert not list((Path(app.config["CLOUDSIM"].instance_dir) / "staging").glob("*"))


def test_a_partial_copy_is_resumed_and_a_foreign_one_caught(
    app: Flask, run: Run, sim: SSHTarget, collect: Callable[..., list[str]], tmp_path: Path
) -> None:
    whole = (Path(run_dir(run.id)) / "state.msgpack").read_bytes()
    partial = tmp_path / "staging" / ".state.msgpack.part"
    partial.parent.mkdir()
    partial.write_bytes(b"x" * 1000)  # left by a copy of another file: caught by the checksum
    lines: list[str] = []
    problems = collect(run, sim, lines)
    assert len(problems) == 1 and "state.msgpack: checksum mismatch" in problems[0]
    assert "state.msgpack" not in {a.filename for a in run.artifacts}  # nothing stored
    assert not partial.exists()  # the next try starts over

    partial.write_bytes(whole[: 5 << 20])  # what a killed copy leaves
    lines.clear()
    assert collect(run, sim, lines) == []
    assert any(f"resuming at byte {5 << 20}" in line for line in lines)
    state = next(a for a in run.artifacts if a.filename == "state.msgpack")
    assert state.sha256 == hashlib.sha256(whole).hexdigest() and state.size == len(whole)


def test_a_machine_with_another_host_key_is_refused(
    app: Flask,
    run: Run,
    sim: SSHTarget,
    sshd_factory: Callable[..., SshServer],  # noqa: F811
    collect: Callable[..., list[str]],
    host_keys: HostKeys,
) -> None:
    host_keys.put("sim", sshd_factory().host_key_line)  # pinned: another machine's key
    lines: list[str] = []
    problems = collect(run, sim, lines)
    assert problems and all("host key of machine 'sim' changed" in p for p in problems)
    assert run.artifacts == []
    store = LogStore(app.config["CLOUDSIM"])
    assert not store.holds(store.object_name(run.id, "state.msgpack"), STATE_BYTES)
