"""Every shell and Python example of the README, simulator/README.md, router/README.md and
docs/ runs, against a real CloudSim (`cloudsim up`) or a real simulator this test starts."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import pytest

from docs_tools.examples import Example, all_examples
from tests.support.up import Up, cloudsim_up

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = all_examples(ROOT)
TOKEN = "cst_docs-examples-admin-token-0123456789"
# Where the examples say CloudSim and the simulator are, and where this test serves them.
DOCUMENTED_URL = "http://127.0.0.1:5000"
DOCUMENTED_SIM = '"10.0.0.2", 7700'
# The examples that cannot run here (each says why in its page), by page and the start of
# their first line. Adding one is a decision: name it here too.
SKIPPED = {
    ("README.md", "make run     # install what is missing, "),
    ("README.md", "make docs-serve   # then open http://127"),
    ("docs/organisers/constellations.md", "cloudsim provider configure servers --in"),
    ("docs/monitoring.md", "export CLOUDSIM_DATABASE_URL=postgresql+"),
    ("docs/team-instances.md", "cloudsim instance restore-access team-a"),
}


def _param(example: Example) -> object:
    marks: list[pytest.MarkDecorator] = []
    if example.xfail:
        # only the documented failure counts: failing otherwise is a failure of the test
        marks.append(pytest.mark.xfail(strict=True, reason=example.xfail, raises=DocumentedFailure))
    return pytest.param(example, id=example.id, marks=marks)


def test_the_skipped_examples_are_the_named_few() -> None:
    # each by its page and the start of its first line (line numbers move with every edit)
    skipped = {(e.path, e.code.splitlines()[0][:40]) for e in EXAMPLES if e.mode == "skip"}
    assert skipped == SKIPPED


@pytest.fixture(scope="module")
def system(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Up]:
    """A CloudSim as `make run` starts it (no demo), its admin the default one, holding TOKEN."""
    settings = {"CLOUDSIM_ADMIN_TOKEN": TOKEN, "CLOUDSIM_ADMIN_EMAIL": "admin@example.org"}
    with cloudsim_up(tmp_path_factory.mktemp("docs-up"), ROOT, **settings) as up:
        yield up


def _run(example: Example, env: dict[str, str], cwd: Path) -> subprocess.CompletedProcess[str]:
    if example.language == "python":
        command = [sys.executable, "-c", example.code]
    else:
        command = ["bash", "-euo", "pipefail", "-c", example.code]
    return subprocess.run(
        command, env=env, cwd=cwd, capture_output=True, text=True, timeout=300, check=False
    )


class DocumentedFailure(Exception):
    """An example marked xfail failed with the error its mark quotes."""


def _checked(example: Example, result: subprocess.CompletedProcess[str]) -> None:
    quoted = re.search(r'"([^"]+)"', example.xfail)
    if result.returncode != 0 and quoted and quoted[1] in result.stdout + result.stderr:
        raise DocumentedFailure(f"{example.id} failed as documented: {quoted[1]}")
    assert result.returncode == 0, (
        f"{example.id} failed ({result.returncode}):\n{example.code}\n"
        f"--- stdout\n{result.stdout}\n--- stderr\n{result.stderr}"
    )


def _workdir(tmp_path: Path) -> Path:
    """A folder like the checkout's root: `.venv/bin/...` as the examples call it."""
    (tmp_path / ".venv").symlink_to(Path(sys.executable).parents[1])
    return tmp_path


def _path_env(base: dict[str, str]) -> dict[str, str]:
    """The environment with `.venv/bin` first on PATH and the checkout on PYTHONPATH."""
    bin_dir = str(Path(sys.executable).parent)
    return dict(base, PATH=f"{bin_dir}{os.pathsep}{base.get('PATH', '')}", PYTHONPATH=str(ROOT))


@pytest.mark.parametrize("example", [_param(e) for e in EXAMPLES if e.mode == "cloudsim"])
def test_example_runs_against_cloudsim(example: Example, system: Up, tmp_path: Path) -> None:
    # made-up cloud keys: configuring a provider only stores them (encrypted), calls no cloud
    aws = {"AWS_ACCESS_KEY_ID": "AKIAEXAMPLEEXAMPLE", "AWS_SECRET_ACCESS_KEY": "made-up-secret"}
    env = _path_env(system.env) | {"TOKEN": TOKEN} | aws
    example = _against(example, f"http://{system.address}")
    _checked(example, _run(example, env, _workdir(tmp_path)))


@pytest.mark.parametrize("example", [_param(e) for e in EXAMPLES if e.mode == "standalone"])
def test_standalone_example_runs(example: Example, tmp_path: Path) -> None:
    _checked(example, _run(example, _path_env(dict(os.environ)), _workdir(tmp_path)))


@pytest.fixture
def simulator(tmp_path: Path) -> Iterator[int]:
    """A lock-step `drcsim serve` of vrc_task_2 on a free loopback port; its command port."""
    from drcsim.bench import start_server, wait_ready

    process, port = start_server("vrc_task_2", "1", ["--lockstep"], None, tmp_path / "sim.log")
    try:
        wait_ready(port, process)
        yield port
    finally:
        process.terminate()
        process.wait(timeout=30)


@pytest.mark.parametrize("example", [_param(e) for e in EXAMPLES if e.mode == "drcsim"])
def test_simulator_example_runs(example: Example, simulator: int, tmp_path: Path) -> None:
    assert DOCUMENTED_SIM in example.code, "the example names the simulator as the docs say"
    code = example.code.replace(DOCUMENTED_SIM, f'"127.0.0.1", {simulator}')
    env = _path_env(dict(os.environ))
    _checked(example, _run(replace(example, code=code), env, _workdir(tmp_path)))


def _against(example: Example, url: str) -> Example:
    return replace(example, code=example.code.replace(DOCUMENTED_URL, url))
