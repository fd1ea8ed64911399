"""A `cloudsim` constellation: a machine that runs its own CloudSim, reachable from outside."""

from __future__ import annotations

import io
import re
import subprocess
import zipfile

from flask import Flask

from cloudsim.auth.policy import SYSTEM
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.launched_constellations import service
from cloudsim.models import ConstellationState, JobState
from cloudsim.providers.service import open_provider
from tests.launched_constellations.conftest import finished, leftovers


def test_cloudsim_kind_serves_its_own_cloudsim(
    constellations_app: Flask, constellations_worker: None, constellations_config: Config
) -> None:
    constellation, job = service.launch(SYSTEM, name="teamsim", kind="cloudsim", provider="local")
    done = finished(job.id)
    assert done.state == JobState.SUCCEEDED, f"{done.error}\n{done.log[-3000:]}"
    db.session.refresh(constellation)
    assert constellation.state == ConstellationState.READY
    server = constellation.machines[0]
    assert [c["ok"] for c in server.verification["checks"]] == [True, True]
    _, bundle = service.ssh_bundle(SYSTEM, constellation.id)
    admin = zipfile.ZipFile(io.BytesIO(bundle)).read("cloudsim-admin.txt").decode()
    password = re.search(r"password: (\S+)", admin).group(1)  # type: ignore[union-attr]
    assert password not in done.log  # the job log masks it
    # "The internet" (the local public network) fetches the team CloudSim's login page.
    probe = open_provider("local", constellations_config).driver.ex_public_proxy_command
    argv = probe(server.public_ip, 5000)
    assert argv is not None
    answer = _http_get(argv, "/login")
    assert answer.startswith(b"HTTP/1.0 200") and b"Log in" in answer
    finished(service.terminate(SYSTEM, constellation.id).id)
    assert leftovers(constellations_config) == {"netns": [], "mounts": [], "files": []}


def _http_get(connect: list[str], path: str) -> bytes:
    """Send an HTTP/1.0 request over a connecting command; read until the server closes."""
    with subprocess.Popen(connect, stdin=subprocess.PIPE, stdout=subprocess.PIPE) as client:
        assert client.stdin is not None and client.stdout is not None
        client.stdin.write(f"GET {path} HTTP/1.0\r\nHost: team\r\n\r\n".encode())
        client.stdin.flush()
        answer = client.stdout.read()  # HTTP/1.0: the server closes after its answer
        client.stdin.close()
        client.wait(30)
    return answer
