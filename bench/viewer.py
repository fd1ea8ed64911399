"""Benchmark the 3D viewer: the pose topic's cost on the simulator, bytes per live viewer,
time to the first frame of a 30-minute replay, and how many live viewers one web worker serves.

Runs without root: the simulator in-process, CloudSim under gunicorn with ONE worker, a
private Redis and SQLite. The live relay's place is taken by a feeder that writes real
frames into Redis at CLOUDSIM_VIEWER_LIVE_HZ, as the relay job does, so the figures are the
web worker's. Every figure comes with a reference measured in the same run.
Usage: python -m bench.viewer [--minutes 30] [--seconds 10]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import msgpack
import redis
import requests
from drcsim.engine import RunOptions, Simulation
from drcsim.protocol import encode
from drcsim.rundir import META, STATE
from drcsim.runlog import read_states

from bench.web import free_port
from cloudsim import migrate
from cloudsim.app import create_app
from cloudsim.auth.passwords import hash_password
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.models import Role, Run, RunState, Task, Team, User, utcnow
from cloudsim.viewer.live import store_frame
from tests.competition.support import store_log
from tests.support.servers import bench_redis

PASSWORD = "benchmark password"
POLL_S = 0.5  # what viewer.js does with the default CLOUDSIM_VIEWER_POLL_MS (2 x 250 ms)


def rtf_with_and_without_poses(seconds: float) -> dict[str, float]:
    """Return the RTF of vrc_task_2 (walking) without and with a `poses` subscriber."""
    results: dict[str, list[float]] = {"without": [], "with": []}
    for _ in range(2):  # alternate, so a change in the machine's load hits both alike
        for label in ("without", "with"):
            sent = {"bytes": 0}

            def publish(_: str, message: dict[str, Any], sent: dict[str, int] = sent) -> None:
                sent["bytes"] += len(encode(message))  # encoding is part of the topic's cost

            sim = Simulation("vrc_task_2", "1", RunOptions(publish=publish))
            if label == "with":
                sim.active_topics = {"poses"}
            sim.apply_command({"op": "behaviour", "name": "walk", "pose": [8.0, 0.0, 0.0]})
            started = time.perf_counter()
            sim.step(round(seconds * 1000))
            results[label].append(sim.sim_time / (time.perf_counter() - started))
            sim.close()
    return {k: statistics.mean(v) for k, v in results.items()}


def long_run_logs(folder: Path, minutes: float) -> Path:
    """Write a run's logs whose state log covers `minutes` (a real 10 s walk, repeated)."""
    short = folder / "short"
    sim = Simulation("vrc_task_2", "1", RunOptions(log_dir=short, time_limit_s=10.0))
    sim.apply_command({"op": "behaviour", "name": "walk", "pose": [6.0, 0.0, 0.0]})
    while not sim.ended:
        sim.step(1000)
    sim.close()
    records = [r for r in read_states(short) if r["step"] > 0]
    out = folder / "long"
    out.mkdir()
    shutil.copy(short / META, out / META)
    packer = msgpack.Packer()
    total = round(minutes * 60 * 100)
    with (out / STATE).open("wb") as handle:
        for index in range(total):
            record = dict(records[index % len(records)])
            record["step"] = 10 * (index + 1)
            record["t"] = (index + 1) / 100
            handle.write(packer.pack(record))
    return out


def seed(env: dict[str, str], logs: Path, minutes: float) -> tuple[int, int]:
    """Fill a fresh database: an officer, a finished run with the long logs, a running run."""
    app = create_app(Config.from_env(env))
    migrate.upgrade(app)
    with app.app_context():
        team = Team(name="Bench")
        db.session.add(team)
        db.session.flush()
        db.session.add(
            User(
                email="officer@example.org",
                role=Role.OFFICER,
                password_hash=hash_password(PASSWORD),
            )
        )
        now = utcnow()
        task = Task(
            team_id=team.id,
            name="Bench walk",
            world="vrc_task_2",
            run_config=1,
            window_start=now,
            window_stop=now,
            uplink_bits=1,
            downlink_bits=1,
        )
        db.session.add(task)
        db.session.flush()
        finished = Run(task_id=task.id, team_id=team.id, state=RunState.FINISHED)
        finished.sim_seconds = minutes * 60
        live = Run(task_id=task.id, team_id=team.id, state=RunState.RUNNING)
        db.session.add_all([finished, live])
        db.session.flush()
        for filename in (META, STATE):
            store_log(finished, logs / filename, filename)
        db.session.commit()
        return finished.id, live.id


def log_in(base: str) -> requests.Session:
    session = requests.Session()
    page = session.get(f"{base}/login", timeout=30).text
    token = re.search(r'name="csrf_token" type="hidden" value="([^"]+)"', page)
    assert token
    session.post(
        f"{base}/login",
        timeout=30,
        data={"email": "officer@example.org", "password": PASSWORD, "csrf_token": token[1]},
    )
    return session


def replay_first_frame(base: str, run_id: int, minutes: float) -> dict[str, float]:
    """Time the page's first requests of a replay: cold start, a seek to the end, again."""
    session = log_in(base)
    started = time.perf_counter()
    assert session.get(f"{base}/runs/{run_id}/view/scene", timeout=120).ok
    first = session.get(f"{base}/runs/{run_id}/view/frames?start=0&seconds=10", timeout=300)
    assert first.ok and first.json()["frames"]
    cold = time.perf_counter() - started
    end = minutes * 60 - 10
    timings = []
    for _ in range(2):
        started = time.perf_counter()
        seek = session.get(f"{base}/runs/{run_id}/view/frames?start={end}&seconds=10", timeout=300)
        assert seek.ok and seek.json()["frames"]
        timings.append(time.perf_counter() - started)
    return {"cold_s": cold, "first_seek_end_s": timings[0], "seek_end_s": timings[1]}


class Feeder(threading.Thread):
    """Writes real frames into the run's live buffer at the relay's rate, as the relay does."""

    def __init__(self, client: redis.Redis, run_id: int, hz: int) -> None:
        super().__init__(daemon=True)
        self.client, self.run_id, self.hz = client, run_id, hz
        self.stop = threading.Event()
        self.bytes = 0
        sim = Simulation("vrc_task_2", "1")
        sim.apply_command({"op": "behaviour", "name": "walk", "pose": [8.0, 0.0, 0.0]})
        self.frames = []
        for _ in range(50):
            sim.step(1000 // hz)
            self.frames.append(sim.poses.frame(sim.sim_time, sim.step_count))
        sim.close()

    def run(self) -> None:
        key = f"cloudsim:viewer:run:{self.run_id}:"
        self.client.set(key + "relay", "running", ex=3600)  # the feeder is the relay
        t, index = 0.0, 0
        while not self.stop.is_set():
            t += 1 / self.hz
            frame = dict(self.frames[index % len(self.frames)], t=round(t, 6))
            self.bytes += len(json.dumps(frame, separators=(",", ":")))
            store_frame(self.client, self.run_id, frame, 10 * self.hz)
            index += 1
            time.sleep(1 / self.hz)


def poll_viewers(base: str, path: str, count: int, seconds: float) -> dict[str, float]:
    """Let `count` viewers poll `path` every POLL_S like the page; return rate, latency, bytes."""
    sessions = [log_in(base) for _ in range(count)]
    latencies: list[float] = []
    received = {"bytes": 0, "errors": 0}
    codes: dict[int, int] = {}
    lock = threading.Lock()
    deadline = time.monotonic() + seconds

    def viewer(number: int, session: requests.Session) -> None:
        newest = -1.0
        time.sleep(POLL_S * number / count)  # viewers do not poll in lockstep
        while time.monotonic() < deadline:
            started = time.perf_counter()
            url = f"{base}{path}?viewer=tab{number}&after={newest}"
            response = session.get(url, timeout=30)
            took = time.perf_counter() - started
            with lock:
                latencies.append(took)
                received["bytes"] += len(response.content)
                received["errors"] += response.status_code != 200
                codes[response.status_code] = codes.get(response.status_code, 0) + 1
            if response.ok and "frames" in (body := response.json()) and body["frames"]:
                newest = body["frames"][-1]["t"]
            time.sleep(max(0.0, POLL_S - took))

    threads = [threading.Thread(target=viewer, args=(n, s)) for n, s in enumerate(sessions)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    latencies.sort()
    return {
        "rate": len(latencies) / seconds,
        "wanted": count / POLL_S,
        "p50_ms": 1000 * statistics.median(latencies),
        "p95_ms": 1000 * latencies[int(0.95 * (len(latencies) - 1))],
        "bytes_per_s": received["bytes"] / seconds,
        "errors": received["errors"],
        "codes": codes,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=30.0, help="length of the replayed run")
    parser.add_argument("--seconds", type=float, default=10.0, help="per measurement")
    args = parser.parse_args()
    print(f"viewer benchmark (load: {os.getloadavg()[0]:.2f})")
    rtf = rtf_with_and_without_poses(args.seconds)
    print(
        f"simulator RTF, vrc_task_2 walking: {rtf['without']:.2f} without a poses subscriber, "
        f"{rtf['with']:.2f} with one (ratio {rtf['with'] / rtf['without']:.3f})"
    )
    instance = Path(tempfile.mkdtemp(prefix="cloudsim-bench-viewer-"))
    redis_server = bench_redis(instance)
    web = free_port()
    env = dict(
        os.environ,
        CLOUDSIM_INSTANCE_DIR=str(instance / "instance"),
        CLOUDSIM_REDIS_URL=redis_server.url(),
        CLOUDSIM_LOG_LEVEL="WARNING",
        CLOUDSIM_LOGIN_LIMIT="10000 per minute",
        CLOUDSIM_ARGON2_TIME_COST="1",
        CLOUDSIM_ARGON2_MEMORY_KIB="1024",
        CLOUDSIM_VIEWER_MAX_LIVE="10000",
    )
    gunicorn = None
    try:
        logs = long_run_logs(instance, args.minutes)
        finished, live = seed(env, logs, args.minutes)
        argv = [sys.executable, "-m", "gunicorn", "--bind", f"127.0.0.1:{web}", "--workers", "1"]
        gunicorn = subprocess.Popen(
            [*argv, "cloudsim.wsgi:app"], env=env, cwd=Path.cwd(), stderr=subprocess.DEVNULL
        )
        base = f"http://127.0.0.1:{web}"
        deadline = time.monotonic() + 60
        while True:
            try:
                requests.get(f"{base}/login", timeout=10)
                break
            except requests.RequestException:  # not listening yet, or still importing
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.2)
        size_mb = (logs / STATE).stat().st_size / 1e6
        started = time.perf_counter()
        count = sum(1 for _ in read_states(logs))
        scan = time.perf_counter() - started
        first = replay_first_frame(base, finished, args.minutes)
        print(
            f"replay of a {args.minutes:g}-minute run ({size_mb:.0f} MB state log, {count} "
            f"records): first frame {first['cold_s']:.2f} s cold (copy from the store, build "
            f"the world, first chunk); seek to the end {first['first_seek_end_s']:.2f} s the "
            f"first time, {first['seek_end_s']:.2f} s after; reference: reading the state log "
            f"once {scan:.2f} s (ratio {first['first_seek_end_s'] / scan:.2f})"
        )
        feeder = Feeder(redis.Redis.from_url(redis_server.url()), live, 10)
        feeder.start()
        time.sleep(1.0)
        fed = feeder.bytes
        one = poll_viewers(base, f"/runs/{live}/view/live", 1, args.seconds)
        relayed = (feeder.bytes - fed) / (args.seconds + 1.0)
        print(
            f"one live viewer: {one['bytes_per_s'] / 1000:.1f} kB/s received (10 frames/s of "
            f"vrc_task_2; reference: the relayed frames alone {relayed / 1000:.1f} kB/s, "
            f"ratio {one['bytes_per_s'] / relayed:.2f})"
        )
        print("viewers  polls/s (wanted)  p50 ms  p95 ms  errors | status page p95 ms (reference)")
        for viewers in (10, 20, 40, 80):
            got = poll_viewers(base, f"/runs/{live}/view/live", viewers, args.seconds)
            ref = poll_viewers(base, f"/runs/{live}/status", viewers, args.seconds)
            print(
                f"{viewers:7d}  {got['rate']:7.1f} ({got['wanted']:5.1f})  {got['p50_ms']:6.1f}  "
                f"{got['p95_ms']:6.1f}  {got['errors']:6d} | {ref['p95_ms']:6.1f}"
            )
            if got["errors"]:
                print(f"         answers: {got['codes']}")
        feeder.stop.set()
    finally:
        if gunicorn is not None:
            gunicorn.send_signal(signal.SIGTERM)
            gunicorn.wait(30)
        redis_server.stop()
        shutil.rmtree(instance, ignore_errors=True)


if __name__ == "__main__":
    main()
