"""A field computer's login record kept with a run's logs: copied once into the run's folder
when it stops, then collected and checksummed like every run log (a real sshd on 127.0.0.1
plays fc1; test_team_access.py reads a real one, written by PAM, on a local vrc)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
from flask import Flask

from cloudsim.competition import login_logs
from cloudsim.competition.artifacts import LogStore, collect_logs, run_dir
from cloudsim.competition.login_logs import snapshot_login_logs
from cloudsim.models import Run
from provisioners.remote.ssh import HostKeys, SSHExecutor, SSHTarget
from tests.competition.test_log_collection import run, runs_dir  # noqa: F401 (fixtures)
from tests.provisioners.remote.ssh.conftest import (  # noqa: F401 (fixtures)
    client_key,
    privsep_dir,
    sshd_factory,
)
from tests.provisioners.remote.ssh.sshd_server import KeyPair, SshServer

LINE = "1796061790\t2026-11-27T22:03:10Z\tlogin\talice-7\talice@example.org\t10.8.0.6\n"


@pytest.fixture
def fc1(sshd_factory: Callable[..., SshServer], client_key: KeyPair) -> SSHTarget:  # noqa: F811
    """Return fc1 as the run's jobs name it: a real sshd on 127.0.0.1."""
    server = sshd_factory()
    return SSHTarget(
        name="vrc-a/fc1", host="127.0.0.1", port=server.port, private_key=client_key.private_pem
    )


def test_the_record_is_copied_once_at_the_stop_and_stored_with_the_run(
    app: Flask,
    run: Run,  # noqa: F811
    fc1: SSHTarget,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    record = tmp_path / "logins.tsv"
    record.write_text(LINE)
    monkeypatch.setattr(login_logs, "LOGIN_LOG", str(record))
    with SSHExecutor(HostKeys()) as executor:
        snapshot_login_logs(executor, [fc1], run.id)
        record.write_text(LINE + LINE.replace("login", "logout"))  # after the stop
        snapshot_login_logs(executor, [fc1], run.id)  # a resumed stop keeps the first copy
        lines: list[str] = []
        problems = collect_logs(
            run,
            executor,
            {"fc1": fc1},
            LogStore(app.config["CLOUDSIM"]),
            tmp_path / "staging",
            lines.append,
        )
    assert problems == [], lines
    assert Path(run_dir(run.id), "logins-fc1.tsv").read_text() == LINE
    (stored,) = [a for a in run.artifacts if a.kind == "logins"]
    assert stored.filename == "logins-fc1.tsv" and stored.size == len(LINE.encode())
    store = LogStore(app.config["CLOUDSIM"])
    assert list(store.lines(stored.location)) == [LINE.rstrip("\n")]


def test_no_record_yet_gives_an_empty_log_not_a_missing_one(
    app: Flask,
    run: Run,  # noqa: F811
    fc1: SSHTarget,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(login_logs, "LOGIN_LOG", str(tmp_path / "never-written.tsv"))
    with SSHExecutor(HostKeys()) as executor:
        snapshot_login_logs(executor, [fc1], run.id)
    assert Path(run_dir(run.id), "logins-fc1.tsv").read_text() == ""
