"""Who may watch a run in 3D and how: its scene, and replay frames from its stored state log."""

from __future__ import annotations

import contextlib
import functools
import json
import os
import shutil
import threading
from collections import OrderedDict
from pathlib import Path
from typing import TYPE_CHECKING, Any

from drcsim import rundir
from sqlalchemy import select

from cloudsim.competition.artifacts import LogStore, artifact_for
from cloudsim.competition.runs import LIVE, get_run
from cloudsim.config import Config
from cloudsim.errors import Conflict, Forbidden, InvalidInput
from cloudsim.extensions import db
from cloudsim.models import Role, Run, RunState, User, World

if TYPE_CHECKING:
    from drcsim.viewer import StateLogPoses

# drcsim.viewer builds worlds in pybullet: it is imported where a scene or a replay is made,
# so that the web app and the command line start without the physics engine.

REPLAY_EVERY = 3  # every third 100 Hz state record: 33 frames per simulated second
MAX_CHUNK_SECONDS = 30.0
OPEN_REPLAYS = 4  # state logs kept open (a built world each) per web process
CACHED_REPLAYS = 20  # runs whose logs stay copied in INSTANCE_DIR/viewer/
REPLAY_LOGS = (rundir.META, rundir.STATE)
LIVE_IS_FOR_OFFICERS = (
    "a live run is shown in 3D to officers only; your team can replay it when it has ended"
)


def mode_for(actor: User, run: Run) -> str:
    """Return how the actor may view the run ("live" or "replay"); raise when not at all."""
    if run.state in LIVE:
        if not actor.has_role(Role.OFFICER):
            # fairness: a team sees its live run only through its metered link
            raise Forbidden(LIVE_IS_FOR_OFFICERS)
        return "live"
    return "replay"


def viewable_run(actor: User, run_id: int) -> tuple[Run, str]:
    """Return a run the actor may view in 3D and how (another team's run: 404)."""
    run = get_run(actor, run_id)
    return run, mode_for(actor, run)


def live_run_for(actor: User, run_id: int) -> Run:
    """Return a running run the actor may watch live."""
    run, mode = viewable_run(actor, run_id)
    if mode != "live" or run.state != RunState.RUNNING:
        raise Conflict(f"run {run.id} is {run.state.value}: there is nothing to watch live")
    return run


@functools.lru_cache(maxsize=16)
def _scene(world: str, config: str, document: str) -> dict[str, Any]:
    from drcsim.viewer import world_scene

    return world_scene(world, config, json.loads(document) if document else None)


def scene_for(run: Run, config: Config) -> dict[str, Any]:
    """Return the run's world as the simulator built it (same document, configuration, seed)."""
    document = world_of(run, config)
    text = json.dumps(document, sort_keys=True) if document is not None else ""
    return _scene(run.task.world, str(run.task.run_config), text)


def world_of(run: Run, config: Config) -> dict[str, Any] | None:
    """Return the world document a run was built from: the one kept with its logs, else (a
    live run's) the one this CloudSim holds; None for a run made before worlds were stored."""
    kept = artifact_for(run, rundir.WORLD)
    if kept is not None:
        found: dict[str, Any] = json.loads(b"".join(LogStore(config).stream(kept.location)))
        return found
    stored = db.session.scalar(select(World).where(World.name == run.task.world))
    return stored.document if stored is not None else None


class _Replays:
    """State logs opened for replay in this process, the least recently used closed first."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.open: OrderedDict[int, tuple[StateLogPoses, threading.Lock]] = OrderedDict()

    def get(self, run_id: int, folder: Path) -> tuple[StateLogPoses, threading.Lock]:
        with self.lock:
            if run_id in self.open:
                self.open.move_to_end(run_id)
                return self.open[run_id]
            from drcsim.viewer import StateLogPoses

            entry = (StateLogPoses(folder), threading.Lock())
            self.open[run_id] = entry
            while len(self.open) > OPEN_REPLAYS:
                _, (old, old_lock) = self.open.popitem(last=False)
                with old_lock:
                    old.close()
            return entry

    def frames(self, run_id: int, folder: Path, start: float, stop: float) -> list[dict[str, Any]]:
        """Return the frames of a run's state log from `start` to `stop` (simulated seconds)."""
        while True:
            poses, lock = self.get(run_id, folder)
            with lock:
                # another request may have closed it between get() and here: open it again
                # (one dict lookup, not self.lock: an eviction holds that while it waits for ours)
                current = self.open.get(run_id)
                if current is not None and current[0] is poses:
                    return list(poses.frames(REPLAY_EVERY, start, stop))


_replays = _Replays()


def _local_logs(run: Run, config: Config) -> Path:
    """Return a local folder with the run's metadata and state log (copied once from the store)."""
    cache = config.instance_dir / "viewer"
    folder = cache / f"run-{run.id}"
    missing = [name for name in REPLAY_LOGS if not (folder / name).exists()]
    if not missing:
        with contextlib.suppress(FileNotFoundError):
            os.utime(folder)  # recently viewed: the last folder to prune
        return folder
    artifacts = {name: artifact_for(run, name) for name in missing}
    for name, artifact in artifacts.items():
        if artifact is None:  # refused before anything is written: no empty folder per request
            raise Conflict(f"run {run.id} has no {name} to replay")
    world = artifact_for(run, rundir.WORLD)  # rebuild the world the run was built from
    if world is not None:
        artifacts[rundir.WORLD] = world
    store = LogStore(config)
    folder.mkdir(parents=True, exist_ok=True)
    for name, artifact in artifacts.items():
        assert artifact is not None
        partial = folder / f".{name}.{os.getpid()}.{threading.get_ident()}.part"
        with partial.open("wb") as out:
            for chunk in store.stream(artifact.location):
                out.write(chunk)
        partial.replace(folder / name)
    _prune(cache, keep=folder)
    return folder


def _viewed_at(folder: Path) -> float:
    try:
        return folder.stat().st_mtime
    except FileNotFoundError:  # pruned by another process meanwhile
        return 0.0


def _prune(cache: Path, keep: Path) -> None:
    """Delete the least recently viewed runs' copies beyond CACHED_REPLAYS (at each new copy)."""
    folders = sorted(
        (f for f in cache.glob("run-*") if f != keep),
        key=_viewed_at,
        reverse=True,
    )
    for old in folders[CACHED_REPLAYS - 1 :]:
        # a process still replaying it copies it again at its next request
        shutil.rmtree(old, ignore_errors=True)


def replay_frames(
    actor: User, run_id: int, start: float, seconds: float, config: Config
) -> dict[str, Any]:
    """Return the frames of a finished run from `start` for `seconds` of simulated time."""
    run, mode = viewable_run(actor, run_id)
    if mode != "replay":
        raise Conflict(f"run {run.id} is {run.state.value}: watch it live, replay it afterwards")
    if not (start >= 0 and 0 < seconds <= MAX_CHUNK_SECONDS):
        raise InvalidInput(f"start must be >= 0 and seconds within (0, {MAX_CHUNK_SECONDS:g}]")
    frames = _replays.frames(run.id, _local_logs(run, config), start, start + seconds)
    return {"start": start, "seconds": seconds, "frames": frames}


def scene_answer(actor: User, run_id: int, config: Config) -> dict[str, Any]:
    """Return what a viewer loads first: the run, its score marks and its world's shapes."""
    run, mode = viewable_run(actor, run_id)
    return {
        "run": {
            "id": run.id,
            "state": run.state.value,
            "mode": mode,
            "world": run.task.world,
            "config": run.task.run_config,
            "sim_seconds": run.sim_seconds,
            "score": run.score,
            "falls": run.falls,
        },
        "marks": score_marks(run),
        "scene": scene_for(run, config),
    }


def score_marks(run: Run) -> list[dict[str, Any]]:
    """Return the run's score events as timeline marks."""
    return [
        {
            "t": e.sim_time,
            "kind": e.kind,
            "label": e.description or e.kind,
            "points": e.points,
        }
        for e in run.score_events
    ]
