"""`drcsim watch`: follow a running server's poses and score as JSON lines on stdout.

CloudSim runs this on the sim machine over SSH to relay a live run to its viewers: the
simulator's ports never leave the LAN, and one watcher serves any number of viewers.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import IO

from drcsim.client import SimClient


def watch(
    server: str,
    port: int,
    rate_hz: float,
    seconds: float,
    out: IO[str] | None = None,
) -> int:
    """Print poses (at most `rate_hz` per simulated second) and score events; return frames."""
    out = out or sys.stdout
    sent, last_t = 0, -1.0
    deadline = time.monotonic() + seconds
    with SimClient(server, port, timeout_s=10.0) as client:
        client.hello()  # learns the topics port; fails fast when the server is not there
        client.subscribe("poses", "score")
        while time.monotonic() < deadline:
            received = client.receive(timeout_s=0.5)
            if received is None:
                continue
            topic, message = received
            if topic == "poses":
                if message["t"] - last_t < 1.0 / rate_hz - 1e-9:
                    continue
                last_t = message["t"]
                sent += 1
                out.write(json.dumps({"frame": message}, separators=(",", ":")) + "\n")
            elif topic == "score":
                out.write(json.dumps({"score": message}) + "\n")
            out.flush()
    return sent


def print_log_frames(log_dir: Path, every: int, out: IO[str] | None = None) -> int:
    """Print the scene, then the frames rebuilt from a run's state log; return how many."""
    out = out or sys.stdout
    from drcsim.viewer import StateLogPoses

    poses = StateLogPoses(log_dir)
    try:
        out.write(json.dumps({"scene": poses.scene()}) + "\n")
        count = 0
        for frame in poses.frames(every):
            out.write(json.dumps({"frame": frame}, separators=(",", ":")) + "\n")
            count += 1
        return count
    finally:
        poses.close()
