"""`drcsim watch`: follow a running server's poses and score as JSON lines on stdout.

CloudSim runs this on the sim machine over SSH to relay a live run to its viewers: the
simulator's ports never leave the LAN, and one watcher serves any number of viewers. The poses
are ground truth, so the server publishes them only on its loopback topics port: this runs on
the sim machine or sees nothing.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import IO

import msgpack
import zmq

from drcsim.client import LOCAL_PORT_OFFSET
from drcsim.errors import ClientError

FIRST_MESSAGE_S = 10.0  # the clock ticks at 100 Hz of simulated time: silence means no server


def watch(
    port: int,
    rate_hz: float,
    seconds: float,
    out: IO[str] | None = None,
    local_port: int | None = None,
) -> int:
    """Print poses (at most `rate_hz` per simulated second) and score events; return frames.

    `port` is the server's command port; its loopback topics port is `local_port`, by
    default the command port + LOCAL_PORT_OFFSET (as `drcsim serve` binds it).
    """
    out = out or sys.stdout
    endpoint = f"tcp://127.0.0.1:{local_port or port + LOCAL_PORT_OFFSET}"
    sent, last_t, heard = 0, -1.0, False
    started = time.monotonic()
    context = zmq.Context()
    sock = context.socket(zmq.SUB)
    sock.linger = 0
    try:
        sock.connect(endpoint)
        for wanted in (b"poses", b"score", b"clock"):
            sock.setsockopt(zmq.SUBSCRIBE, wanted)
        while (now := time.monotonic()) < started + seconds:
            if not heard and now - started >= FIRST_MESSAGE_S:
                raise ClientError(f"nothing published on {endpoint}: is a server running here?")
            if not sock.poll(500):
                continue
            frames = sock.recv_multipart()
            heard, topic = True, frames[0].decode()
            message = msgpack.unpackb(frames[1], raw=False)
            if topic == "poses":
                if message["t"] - last_t < 1.0 / rate_hz - 1e-9:
                    continue
                last_t = message["t"]
                sent += 1
                out.write(json.dumps({"frame": message}, separators=(",", ":")) + "\n")
            elif topic == "score":
                out.write(json.dumps({"score": message}) + "\n")
            out.flush()
    finally:
        sock.close(linger=0)
        context.term()
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
