"""A finished run's own evidence: its stored logs copied into a folder (each checked against the
checksum recorded when it was stored), the master's world document beside them, and drcsim's
deterministic replay run on that folder in its own process."""

from __future__ import annotations

import hashlib
import json
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from drcsim.rundir import COMMANDS, FINAL, META, SCORE, STATE, WORLD, RunScore, read_score_log

from cloudsim.competition.artifacts import LogStore, artifact_for
from cloudsim.errors import CloudSimError
from cloudsim.models import Run, World

# What a replay reads: without any of them the run cannot be re-simulated.
REPLAYED = (META, COMMANDS, STATE, FINAL, SCORE)
REPLAY_SECONDS_MIN = 120.0
REPLAY_SECONDS_PER_SIM_SECOND = 4.0  # a replay runs at several times real time; this is slack
ERROR_PREFIX = "drcsim: error: "


class Held(CloudSimError):
    """The run's evidence does not prove its result: it is held for review with this reason."""


class ReplayFailed(CloudSimError):
    """The replay itself could not run (timeout, crash): it proves nothing either way."""


@dataclass(frozen=True)
class Evidence:
    """A run's logs in a folder, ready to replay, and what they say."""

    folder: Path
    meta: dict[str, Any]
    final: dict[str, Any]
    score_log: RunScore


def work_folder(instance_dir: Path, run_id: int) -> Path:
    """Return the folder a run's verification copies its logs into."""
    return instance_dir / "verification" / str(run_id)


def _copy_checked(store: LogStore, run: Run, filename: str, folder: Path) -> None:
    artifact = artifact_for(run, filename)
    if artifact is None:
        raise Held(f"the run has no {filename}: it cannot be re-simulated")
    digest = hashlib.sha256()
    with open(folder / filename, "wb") as copy:
        for chunk in store.stream(artifact.location):
            digest.update(chunk)
            copy.write(chunk)
    if digest.hexdigest() != artifact.sha256:
        raise Held(
            f"{filename} in the log store is not the log that was stored (SHA-256 "
            f"{digest.hexdigest()[:12]}, recorded {artifact.sha256[:12]})"
        )


def _json(folder: Path, filename: str) -> dict[str, Any]:
    try:
        data = json.loads((folder / filename).read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        raise Held(f"{filename} is not JSON: {exc}") from None
    if not isinstance(data, dict):
        raise Held(f"{filename} is not a JSON object")
    return data


def gather(run: Run, store: LogStore, world: World, folder: Path) -> Evidence:
    """Copy the run's logs into `folder` (afresh) beside the master's world document; raise
    Held when a log is missing, changed, or says the run was not the task's."""
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True, mode=0o700)
    for filename in REPLAYED:
        _copy_checked(store, run, filename, folder)
    # The world the master holds, never the one the run brought: a run built from another
    # world has another digest in its metadata, and the replay says so.
    (folder / WORLD).write_text(json.dumps(world.document) + "\n")
    meta, final = _json(folder, META), _json(folder, FINAL)
    task = run.task
    ran = (meta.get("world"), str(meta.get("config")), meta.get("time_limit_s"))
    if ran != (task.world, str(task.run_config), float(task.timeout_s)):
        raise Held(
            f"the logs are of {ran[0]} #{ran[1]} with a {ran[2]} s limit; the task is "
            f"{task.world} #{task.run_config} with {task.timeout_s} s"
        )
    state = hashlib.sha256((folder / STATE).read_bytes()).hexdigest()
    if final.get("state_log_sha256") != state:
        raise Held(
            f"{STATE} is not the state log the simulator closed (its final record's SHA-256)"
        )
    try:
        with open(folder / SCORE) as lines:
            score_log = read_score_log(lines)
    except (ValueError, UnicodeDecodeError) as exc:
        raise Held(f"{SCORE}: {exc}") from None
    return Evidence(folder, meta, final, score_log)


def replay(evidence: Evidence) -> dict[str, Any]:
    """Re-simulate the run with `drcsim replay` in a process of its own; return its result.

    A replay that diverges from the logs raises Held with drcsim's reason; one that cannot run
    (killed, out of time) raises ReplayFailed.
    """
    limit = REPLAY_SECONDS_MIN + REPLAY_SECONDS_PER_SIM_SECOND * float(
        evidence.final.get("sim_time") or evidence.meta.get("time_limit_s") or 0
    )
    argv = [sys.executable, "-m", "drcsim.cli", "replay", str(evidence.folder), "--json"]
    try:
        done = subprocess.run(argv, capture_output=True, text=True, timeout=limit, check=False)
    except subprocess.TimeoutExpired:
        raise ReplayFailed(f"the replay took longer than {limit:.0f} s") from None
    if done.returncode < 0:
        raise ReplayFailed(f"the replay was killed by signal {-done.returncode}")
    if done.returncode != 0:
        lines = done.stderr.strip().splitlines() or ["(no message)"]
        said = next((line for line in lines if line.startswith(ERROR_PREFIX)), lines[-1])
        raise Held(f"the replay of its command log diverged: {said.removeprefix(ERROR_PREFIX)}")
    try:
        result: dict[str, Any] = json.loads(done.stdout.strip().splitlines()[-1])
    except (ValueError, IndexError):
        raise ReplayFailed(f"the replay answered {done.stdout[-200:]!r}") from None
    return result
