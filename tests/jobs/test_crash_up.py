"""The crash suite, part two: the whole `cloudsim up` tree (web, worker, beat, Redis) killed
during a launch and during a terminate, and started again as a user would.

`cloudsim up` on SQLite, as a user runs it, launches a vrc through the API; the tree is
SIGKILLed while the first machines are being made, again while the software is being
installed, and once more while the terminate destroys the machines. After each restart the
job resumes and ends, the API answers no 5xx while it recovers (connection refused while it is
down is no answer), and at the end no host, mount or process of the instance is left and no
key of the constellation remains. (Workers killed at each stage of every job kind:
tests/jobs/test_crash_suite.py.)
"""

from __future__ import annotations

import os
import re
import sqlite3
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import requests

from tests.support.servers import wait_for
from tests.support.up import Up, cloudsim_up

pytestmark = pytest.mark.hosts
PREFIX = f"cu{os.getpid() % 100000}"
PASSWORD = "the crash suite's admin password"
NETWORKS = 238


def _settings() -> dict[str, str]:
    return {
        "CLOUDSIM_ADMIN_PASSWORD": PASSWORD,
        "CLOUDSIM_WEB_WORKERS": "1",
        "CLOUDSIM_LOG_LEVEL": "WARNING",
        "CLOUDSIM_LOCAL_PREFIX": PREFIX,
        "CLOUDSIM_LOCAL_SUBNET_POOL": f"10.{NETWORKS}.0.0/16",
        "CLOUDSIM_LOCAL_PUBLIC_CIDR": f"198.18.{NETWORKS - 200}.0/24",
        "CLOUDSIM_JOB_LEASE_SECONDS": "10",
        # two shared cores: a launch must not fail for the load alone (a slow self-test, the
        # machines' image built once, quiet for minutes)
        "CLOUDSIM_SIM_MIN_RTF": "0.05",
        "CLOUDSIM_JOB_STALL_SECONDS": "1800",
    }


class Watcher:
    """Ask a running `cloudsim up` through its API, as a user watching would: no 5xx."""

    def __init__(self, up: Up, token: str | None = None) -> None:
        self.base = f"http://{up.address}"
        self.session = requests.Session()
        self.token = token or self._token()
        self.session.headers["Authorization"] = f"Bearer {self.token}"
        self.answers: list[tuple[str, int]] = []

    def _token(self) -> str:
        wait_for(lambda: self._get("/readyz").status_code == 200, 300, "cloudsim up ready")
        page = self._get("/login").text
        data = {"email": "root@example.org", "password": PASSWORD, "csrf_token": _csrf(page)}
        assert self.session.post(f"{self.base}/login", data=data, timeout=60).ok
        account = self._get("/account").text
        issued = self.session.post(
            f"{self.base}/account/tokens",
            data={"name": "crash", "csrf_token": _csrf(account)},
            timeout=60,
        ).text
        found = re.search(r'<code id="new-token">([^<]+)</code>', issued)
        assert found, issued[:2000]
        return found.group(1)

    def _get(self, path: str) -> requests.Response:
        return self.session.get(f"{self.base}{path}", timeout=60)

    def get(self, path: str) -> Any:
        """GET an API path; keep the status; return its JSON."""
        answer = self._get(path)
        self.answers.append((path, answer.status_code))
        assert answer.status_code < 500, f"{path}: {answer.status_code} {answer.text[:500]}"
        return answer.json()

    def send(self, method: str, path: str, body: dict[str, Any] | None = None) -> Any:
        answer = self.session.request(method, f"{self.base}{path}", json=body, timeout=60)
        assert answer.status_code < 300, f"{path}: {answer.status_code} {answer.text[:500]}"
        return answer.json()


def _csrf(page: str) -> str:
    found = re.search(r'name="csrf_token" type="hidden" value="([^"]+)"', page)
    assert found, page[:500]
    return found.group(1)


def _hosts(instance: Path) -> Path:
    return instance / "local-hosts"


def _nodes(instance: Path) -> list[Path]:
    """Return the hosts' record files the local provider keeps (one per host it made)."""
    return sorted(_hosts(instance).glob(f"{PREFIX}/nodes/*/record.json"))


def _installing(instance: Path) -> bool:
    """Return whether the software's settings reached a host's own layer (install runs)."""
    return any(_hosts(instance).glob(f"{PREFIX}/hosts/*/upper/etc/cloudsim"))


def _job(instance: Path, job_id: str) -> tuple[str, int]:
    """Return a job's state and attempts, read from the instance's database file."""
    with sqlite3.connect(instance / "cloudsim.db", timeout=30) as conn:
        row = conn.execute("SELECT state, attempts FROM jobs WHERE id = ?", (job_id,)).fetchone()
    return row[0], row[1]


def _crash_when(
    tmp_path: Path, root: Path, token: str | None, when: Callable[[], bool], what: str,
    act: Callable[[Watcher], None] | None = None,
) -> str:  # fmt: skip
    """Start `cloudsim up`, do act, kill its whole tree once when() holds; return the token."""
    with cloudsim_up(tmp_path, root, **_settings()) as up:
        watcher = Watcher(up, token)
        if act is not None:
            act(watcher)
        wait_for(lambda: (watcher.get("/api/v1/constellations"), when())[1], 900, what)
        up.crash()
    return watcher.token


def _recover(tmp_path: Path, root: Path, token: str, job_id: str) -> None:
    """Start `cloudsim up` again; the job resumes and succeeds; no 5xx meanwhile."""
    with cloudsim_up(tmp_path, root, **_settings()) as up:
        watcher = Watcher(up, token)

        def ended() -> bool:
            watcher.get("/api/v1/constellations")
            return watcher.get(f"/api/v1/jobs/{job_id}")["state"] in ("succeeded", "failed")

        wait_for(ended, 1200, f"job {job_id} to end after the restart")
        job = watcher.get(f"/api/v1/jobs/{job_id}")
        assert job["state"] == "succeeded", f"{job['error']}\n{job['log'][-3000:]}"


@pytest.mark.timeout(3000)  # a vrc launched and terminated through three power cuts
def test_the_whole_up_tree_killed_during_launch_and_terminate_loses_nothing(
    tmp_path: Path, pytestconfig: pytest.Config
) -> None:
    root, instance = pytestconfig.rootpath, tmp_path / "instance"
    launched: dict[str, Any] = {}

    def launch(watcher: Watcher) -> None:
        body = {"name": "crashed", "kind": "vrc", "provider": "local"}
        launched.update(watcher.send("POST", "/api/v1/constellations", body))

    try:
        token = _crash_when(
            tmp_path, root, None, lambda: len(_nodes(instance)) >= 1, "a first machine", launch
        )
        job_id = launched["job"]["id"]
        assert _job(instance, job_id)[0] == "running"
        # started again and killed once more, this time while software is being installed
        token = _crash_when(tmp_path, root, token, lambda: _installing(instance), "the install")
        assert _job(instance, job_id)[0] == "running"
        _recover(tmp_path, root, token, job_id)
        assert _job(instance, job_id)[1] == 3  # one attempt per start of `cloudsim up`
        ref = launched["constellation"]["id"]
        terminating: dict[str, Any] = {}

        def terminate(watcher: Watcher) -> None:
            terminating.update(watcher.send("DELETE", f"/api/v1/constellations/{ref}"))

        count = len(_nodes(instance))
        assert count == 4
        token = _crash_when(
            tmp_path, root, token, lambda: len(_nodes(instance)) < count, "a machine destroyed",
            terminate,
        )  # fmt: skip
        _recover(tmp_path, root, token, terminating["id"])
        with cloudsim_up(tmp_path, root, **_settings()) as up:
            watcher = Watcher(up, token)
            assert watcher.get(f"/api/v1/constellations/{ref}")["state"] == "terminated"
            jobs = watcher.get("/api/v1/jobs?page_size=500")
            assert all(job["state"] in ("succeeded", "failed") for job in jobs), jobs
    finally:
        _sweep(tmp_path, root)
    assert _nodes(instance) == []
    with sqlite3.connect(instance / "cloudsim.db") as conn:
        keys = conn.execute(
            "SELECT count(*) FROM secrets WHERE owner_type = 'constellation'"
        ).fetchone()[0]
    assert keys == 0, "a key of the terminated constellation is left"
    assert _processes_of(tmp_path) == [], "a process of the crashed instance is left"


def _processes_of(folder: Path) -> list[str]:
    """Return the command lines of processes that name the instance's folder."""
    found = []
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit() or int(proc.name) == os.getpid():
            continue
        try:
            line = (proc / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if str(folder) in line:
            found.append(f"{proc.name}: {line[:200]}")
    return found


def _sweep(tmp_path: Path, root: Path) -> None:
    """Remove whatever hosts a failed test left (the provider's own sweep)."""
    from provisioners.providers.local.driver import LocalNodeDriver

    settings = _settings()
    LocalNodeDriver(
        state_dir=str(tmp_path / "instance" / "local-hosts"),
        prefix=PREFIX,
        subnet_pool=settings["CLOUDSIM_LOCAL_SUBNET_POOL"],
        public_cidr=settings["CLOUDSIM_LOCAL_PUBLIC_CIDR"],
    ).ex_sweep()
