"""The run's MCAP log (run.mcap): every topic a robotics tool can open, written as the run goes.

Messages are JSON following Foxglove's well-known schemas where one fits (foxglove.*) and
our own documented JSON schemas otherwise (drcsim.*); every schema travels inside the file.
Log time is simulated time (nanoseconds from the run's start), so tools show the run's own
timeline. The file is chunked and zstd-compressed; each chunk reaches the disk when it is
full, so a simulator that dies leaves a file readable up to its last whole chunk, and a
closed one has a summary section (indexes, statistics) that lets tools seek.
"""

from __future__ import annotations

import base64
import json
import math
import os
import struct
import zlib
from collections.abc import Iterator, Sequence
from functools import cache
from importlib import resources
from pathlib import Path
from typing import IO, Any, cast

import numpy as np
from mcap.exceptions import McapError
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from drcsim.rundir import MCAP

PROFILE = ""  # no ROS profile: plain JSON messages
LIBRARY = "drcsim"
CHUNK_BYTES = 1 << 20  # about 2 s of a run with its body poses: what a crash may lose
# Every topic the simulator writes and its schema (simulator/README.md documents them).
TOPICS = {
    "/world/scene": "foxglove.SceneUpdate",
    "/tf": "foxglove.FrameTransforms",
    "/robot/estimate": "foxglove.PoseInFrame",
    "/team/joint_states": "drcsim.JointStates",
    "/team/imu": "drcsim.Imu",
    "/team/contact": "drcsim.Contact",
    "/team/lidar": "foxglove.LaserScan",
    "/team/camera/left": "foxglove.CompressedImage",
    "/team/camera/right": "foxglove.CompressedImage",
    "/team/robot_state": "drcsim.RobotState",
    "/score": "foxglove.Log",
    "/score/events": "drcsim.ScoreEvent",
    "/commands": "drcsim.Command",
}
# Added by CloudSim when it collects the run (bandwidth.mcap, merged with run.mcap by topic).
BANDWIDTH_TOPIC = "/router/bandwidth"
BANDWIDTH_SCHEMA = "drcsim.Bandwidth"
WORLD_FRAME = "world"
KEY_FRAME_S = 1.0  # every frame's pose is written at least this often
POSE_DECIMALS = 6
# foxglove.Log levels
INFO, WARNING = 2, 3


@cache
def schema_text(name: str) -> str:
    """Return the JSON schema of a message type, as stored in the package (and in each file)."""
    return (resources.files("drcsim.schemas") / f"{name}.json").read_text()


def stamp(sim_time: float) -> dict[str, int]:
    """Return a simulated time as a Foxglove time (seconds and nanoseconds)."""
    nanos = nanoseconds(sim_time)
    return {"sec": nanos // 1_000_000_000, "nsec": nanos % 1_000_000_000}


def nanoseconds(sim_time: float) -> int:
    """Return a simulated time in whole nanoseconds (MCAP's log time)."""
    return max(0, round(sim_time * 1e9))


class _Unbuffered:
    """A file whose every write reaches the OS at once.

    The MCAP writer writes a whole chunk at a time (a few a second at most), and each must
    outlive a crash of the process; the writer wraps a raw file in a buffer of its own, so it
    gets this instead.
    """

    def __init__(self, path: Path) -> None:
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        self._offset = 0

    def write(self, data: bytes | memoryview) -> int:
        view = memoryview(data)
        while view:
            view = view[os.write(self._fd, view) :]
        self._offset += len(data)
        return len(data)

    def tell(self) -> int:
        return self._offset

    def flush(self) -> None:
        """Do nothing: every write is with the OS already."""

    def close(self) -> None:
        os.close(self._fd)


class McapWriter:
    """An MCAP file of JSON messages, a channel per topic registered on first use."""

    def __init__(self, path: Path, metadata: dict[str, dict[str, str]]) -> None:
        self._handle = _Unbuffered(path)
        self._writer = Writer(
            cast(IO[bytes], self._handle), chunk_size=CHUNK_BYTES, compression=CompressionType.ZSTD
        )
        self._writer.start(profile=PROFILE, library=LIBRARY)
        for name, record in metadata.items():
            self._writer.add_metadata(name, record)
        self._channels: dict[str, int] = {}
        self._schemas: dict[str, int] = {}
        self._sequence = 0
        self.closed = False

    def channel(self, topic: str, schema: str) -> int:
        """Return the channel of a topic, registering it and its schema the first time."""
        found = self._channels.get(topic)
        if found is not None:
            return found
        schema_id = self._schemas.get(schema)
        if schema_id is None:
            schema_id = self._writer.register_schema(
                schema, "jsonschema", schema_text(schema).encode()
            )
            self._schemas[schema] = schema_id
        channel_id = self._writer.register_channel(topic, "json", schema_id)
        self._channels[topic] = channel_id
        return channel_id

    def write(self, topic: str, schema: str, sim_time: float, data: bytes) -> None:
        """Write one encoded message at its simulated time."""
        if self.closed:  # a lingering server answering after the run's end
            return
        channel_id = self.channel(topic, schema)
        when = nanoseconds(sim_time)
        self._sequence += 1
        self._writer.add_message(channel_id, when, data, when, sequence=self._sequence)

    def message(self, topic: str, sim_time: float, payload: dict[str, Any]) -> None:
        """Write one message of a documented topic."""
        try:
            data = json.dumps(payload, separators=(",", ":"), allow_nan=False).encode()
        except ValueError:  # JSON has no NaN or infinity: such a reading is written as null
            data = json.dumps(_finite(payload), separators=(",", ":")).encode()
        self.write(topic, TOPICS.get(topic) or BANDWIDTH_SCHEMA, sim_time, data)

    def close(self, metadata: dict[str, dict[str, str]] | None = None) -> None:
        """Write the last chunk, the metadata and the summary section, and close the file."""
        if self.closed:
            return
        for name, record in (metadata or {}).items():
            self._writer.add_metadata(name, record)
        self._writer.finish()
        self._handle.close()
        self.closed = True


def _finite(value: Any) -> Any:
    """Return value with every non-finite float replaced by None."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {key: _finite(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(item) for item in value]
    return value


class TransformEncoder:
    """Encodes the frames' world poses as foxglove.FrameTransforms messages, cheaply.

    A frame is in a message when it moved (at the written precision) since it was last
    written, and every frame is in a key frame (one a second), so a tool that seeks finds the
    whole tree within a second. Written by hand from one template a frame: ~40 frames 100
    times a second is the run's costliest record.
    """

    def __init__(self, frames: Sequence[str]) -> None:
        self.templates = [
            '{"timestamp":%s,"parent_frame_id":"'
            + WORLD_FRAME
            + '","child_frame_id":"'
            + frame.replace('"', "")
            + '","translation":{"x":%.4f,"y":%.4f,"z":%.4f},'
            '"rotation":{"x":%.5f,"y":%.5f,"z":%.5f,"w":%.5f}}'
            for frame in frames
        ]
        self.scale = np.tile([1e4, 1e4, 1e4, 1e5, 1e5, 1e5, 1e5], (len(frames), 1))
        self.last = np.full((len(frames), 7), np.nan)

    def encode(self, sim_time: float, flat: Sequence[float], key: bool) -> bytes:
        """Return the message for now: the frames that moved, or all of them if `key`."""
        values = np.asarray(flat, dtype=np.float64).reshape(len(self.templates), 7)
        if not np.isfinite(values).all():  # JSON has no NaN (a body the physics blew up)
            values = np.nan_to_num(values)
        quantised = np.rint(values * self.scale)
        moved = np.ones(len(values), dtype=bool) if key else (quantised != self.last).any(axis=1)
        self.last[moved] = quantised[moved]
        when = stamp(sim_time)
        time_text = f'{{"sec":{when["sec"]},"nsec":{when["nsec"]}}}'
        rows = values.tolist()
        parts = [
            self.templates[index] % (time_text, *rows[index])
            for index in np.flatnonzero(moved).tolist()
        ]
        return ('{"transforms":[' + ",".join(parts) + "]}").encode()


ESTIMATE_TEMPLATE = (
    '{"timestamp":{"sec":%d,"nsec":%d},"frame_id":"' + WORLD_FRAME + '","pose":{"position":'
    '{"x":%.4f,"y":%.4f,"z":%.4f},"orientation":{"x":%.5f,"y":%.5f,"z":%.5f,"w":%.5f}}}'
)


def estimate_pose(
    sim_time: float, position: Sequence[float], orientation: Sequence[float]
) -> bytes:
    """Return a foxglove.PoseInFrame of the estimated pelvis in the world, encoded."""
    when = stamp(sim_time)
    values = (when["sec"], when["nsec"], *position, *orientation)
    return (ESTIMATE_TEMPLATE % values).encode()


def pose(position: Sequence[float], orientation: Sequence[float]) -> dict[str, Any]:
    """Return a foxglove.Pose."""
    x, y, z = (float(v) for v in position)
    qx, qy, qz, qw = (float(v) for v in orientation)
    return {
        "position": {"x": x, "y": y, "z": z},
        "orientation": {"x": qx, "y": qy, "z": qz, "w": qw},
    }


def png_rgb8(width: int, height: int, pixels: bytes) -> bytes:
    """Return an RGB image (8 bits a channel, rows top to bottom) as a PNG file."""
    stride = 3 * width
    rows = b"".join(b"\x00" + pixels[y * stride : (y + 1) * stride] for y in range(height))

    def block(kind: bytes, body: bytes) -> bytes:
        return (
            struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))
        )

    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + block(b"IHDR", header)
        + block(b"IDAT", zlib.compress(rows, 1))  # level 1: 10 Hz of images, in real time
        + block(b"IEND", b"")
    )


def compressed_image(
    sim_time: float, frame: str, width: int, height: int, pixels: bytes
) -> dict[str, Any]:
    """Return a foxglove.CompressedImage of an rgb8 image, as PNG."""
    return {
        "timestamp": stamp(sim_time),
        "frame_id": frame,
        "data": base64.b64encode(png_rgb8(width, height, pixels)).decode(),
        "format": "png",
    }


def write_bandwidth(path: Path, samples: Sequence[dict[str, Any]]) -> int:
    """Write the router's per-second counts as an MCAP file whose times line up with
    run.mcap's; return how many messages it holds.

    Each sample has `at` (the end of the second it covers, in seconds since the simulator's
    start), `direction`, `bits`, `used_bits` and `cap_bits`; one before the start is left out.
    """
    kept = sorted(
        (sample for sample in samples if sample["at"] >= 0),
        key=lambda sample: (sample["at"], sample["direction"]),
    )
    writer = McapWriter(path, {})
    for sample in kept:
        at = float(sample["at"])
        record = {key: sample[key] for key in ("direction", "bits", "used_bits", "cap_bits")}
        writer.message(BANDWIDTH_TOPIC, at, {"timestamp": stamp(at), **record})
    writer.close()
    return len(kept)


def read_messages(path: Path) -> Iterator[tuple[Schema | None, Channel, Message]]:
    """Yield every message of an MCAP file in file order, reading a file whose writer died
    (no summary, a torn last chunk) up to its last whole chunk."""
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    with path.open("rb") as handle:
        records = StreamReader(handle).records
        while True:
            try:
                record = next(records)
            except StopIteration:
                return
            except (McapError, EOFError, ValueError, struct.error):
                return  # the torn end of a file whose writer died
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message) and record.channel_id in channels:
                channel = channels[record.channel_id]
                yield schemas.get(channel.schema_id), channel, record


def log_path(directory: Path) -> Path:
    """Return where a run directory's MCAP log is."""
    return directory / MCAP
