"""Benchmark run.mcap against the msgpack state log: size, CPU cost and seeking, 30 minutes.

A short real run of vrc_task_2 (the robot walking) is recorded at 100 Hz: every moving
link's pose and the estimate (what run.mcap's /tf and /robot/estimate hold) and the state
vector (what state.msgpack holds). Those ticks, repeated to fill the requested minutes, are
then written both ways; each figure is printed with its ratio to the state log measured in
the same run. The cost of reading the poses out of pybullet is measured while recording and
added to each way's writing (the MCAP log needs link poses, the state log the state vector).
Usage: python -m bench.mcap_log [--minutes 30] [--seconds 20]
"""

from __future__ import annotations

import argparse
import random
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import msgpack
from drcsim.engine import RunOptions, Simulation
from drcsim.mcaplog import McapWriter, TransformEncoder, estimate_pose
from drcsim.mcaprun import LinkPoses, frame_names
from drcsim.protocol import check_command
from drcsim.runlog import RunLog
from drcsim.viewer import describe_scene, moving_bodies, scene_roles
from mcap.reader import make_reader

TICK_S = 0.01
SEEKS = 20


def record(seconds: float) -> dict[str, Any]:
    """Run the walk for `seconds` and return each tick's poses, estimate and state vector,
    with the CPU seconds the physics and each way's reads took."""
    sim = Simulation("vrc_task_2", 1, RunOptions())
    try:
        sim.apply_command(check_command({"op": "behaviour", "name": "walk", "pose": [30, 0, 0]}))
        bodies = moving_bodies(sim.client)
        poses = LinkPoses(sim.client, bodies)
        scene = describe_scene(sim.client, scene_roles(sim))
        names = frame_names(scene, scene_roles(sim))
        ticks: list[tuple[list[float], dict[str, Any], list[float]]] = []
        physics = poses_cpu = vector_cpu = 0.0
        for _ in range(round(seconds / TICK_S)):
            start = time.process_time()
            sim.step(10)
            middle = time.process_time()
            flat = poses.read()
            estimate = sim.estimator.pelvis()
            after_poses = time.process_time()
            vector = sim.state_vector()
            end = time.process_time()
            physics += middle - start
            poses_cpu += after_poses - middle
            vector_cpu += end - after_poses
            ticks.append((flat, estimate, vector))
        frames = [name for body in bodies for name in names[body]]
        return {
            "ticks": ticks,
            "frames": frames,
            "meta": sim.meta(),
            "physics_cpu_per_s": physics / seconds,
            "poses_cpu_per_s": poses_cpu / seconds,
            "vector_cpu_per_s": vector_cpu / seconds,
        }
    finally:
        sim.client.disconnect()


def write_msgpack(folder: Path, recorded: dict[str, Any], count: int) -> float:
    """Write `count` ticks as state.msgpack; return the CPU seconds it took."""
    ticks = recorded["ticks"]
    log = RunLog(folder, recorded["meta"])
    start = time.process_time()
    for index in range(count):
        log.state(10 * (index + 1), (index + 1) * TICK_S, ticks[index % len(ticks)][2])
    log.close({})
    return time.process_time() - start


def write_mcap(path: Path, recorded: dict[str, Any], count: int) -> float:
    """Write `count` ticks as run.mcap's /tf and /robot/estimate; return the CPU seconds."""
    ticks, frames = recorded["ticks"], recorded["frames"]
    start = time.process_time()
    writer = McapWriter(path, {"drcsim.run": {k: str(v) for k, v in recorded["meta"].items()}})
    encoder = TransformEncoder(frames)
    for index in range(count):
        flat, estimate, _ = ticks[index % len(ticks)]
        t = (index + 1) * TICK_S
        data = encoder.encode(t, flat, key=index % 100 == 0)
        writer.write("/tf", "foxglove.FrameTransforms", t, data)
        data = estimate_pose(t, estimate["position"], estimate["orientation"])
        writer.write("/robot/estimate", "foxglove.PoseInFrame", t, data)
    writer.close()
    return time.process_time() - start


def seek_mcap(path: Path, seconds: list[int]) -> list[float]:
    """Return the wall seconds to open the file and read the poses at each given second."""
    took = []
    for second in seconds:
        start = time.perf_counter()
        with path.open("rb") as handle:
            reader = make_reader(handle)
            found = next(reader.iter_messages(topics=["/tf"], starting_at=second * 10**9))
            assert found[2].log_time >= second * 10**9
        took.append(time.perf_counter() - start)
    return took


def seek_msgpack(path: Path, seconds: list[int]) -> list[float]:
    """Return the wall seconds to reach each given second in the state log (it has no index:
    read from the start)."""
    took = []
    for second in seconds:
        start = time.perf_counter()
        with path.open("rb") as handle:
            for record in msgpack.Unpacker(handle, raw=False):
                if record["t"] >= second:
                    break
        took.append(time.perf_counter() - start)
    return took


def main() -> None:
    """Print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=30.0)
    parser.add_argument("--seconds", type=float, default=20.0, help="of real run recorded")
    args = parser.parse_args()
    recorded = record(args.seconds)
    count = round(args.minutes * 60 / TICK_S)
    run_s = count * TICK_S
    with tempfile.TemporaryDirectory(prefix="bench-mcap-") as tmp:
        folder = Path(tmp)
        msgpack_cpu = write_msgpack(folder, recorded, count) + recorded["vector_cpu_per_s"] * run_s
        mcap_cpu = write_mcap(folder / "run.mcap", recorded, count)
        mcap_cpu += recorded["poses_cpu_per_s"] * run_s
        state_size = (folder / "state.msgpack").stat().st_size
        mcap_size = (folder / "run.mcap").stat().st_size
        picks = sorted(random.Random(1).sample(range(int(run_s) - 1), SEEKS))
        mcap_seek = seek_mcap(folder / "run.mcap", picks)
        msgpack_seek = seek_msgpack(folder / "state.msgpack", picks)
    frames = len(recorded["frames"])
    print(f"{args.minutes:g} simulated minutes of vrc_task_2 (walking), {frames} frames")
    print(f"physics alone: {100 * recorded['physics_cpu_per_s']:.1f}% of a core at real time")
    print(
        f"size: run.mcap (/tf + /robot/estimate) {mcap_size / 1e6:.1f} MB, state.msgpack "
        f"{state_size / 1e6:.1f} MB: ratio {mcap_size / state_size:.2f}"
    )
    print(
        f"writing: run.mcap {100 * mcap_cpu / run_s:.2f}% of a core at real time, state.msgpack "
        f"{100 * msgpack_cpu / run_s:.2f}%: ratio {mcap_cpu / msgpack_cpu:.2f}"
    )
    print(
        f"seek to a second ({SEEKS} random ones, open included): run.mcap median "
        f"{1000 * statistics.median(mcap_seek):.1f} ms, max {1000 * max(mcap_seek):.1f} ms; "
        f"state.msgpack median {1000 * statistics.median(msgpack_seek):.1f} ms, "
        f"max {1000 * max(msgpack_seek):.1f} ms: ratio of medians "
        f"{statistics.median(mcap_seek) / statistics.median(msgpack_seek):.3f}"
    )


if __name__ == "__main__":
    main()
