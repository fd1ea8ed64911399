"""The client library team code uses to drive a drcsim server over the network."""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable
from typing import Any

import msgpack
import zmq

from drcsim.commands import CommandAPI
from drcsim.errors import ClientError

# Field computers install drcsim without pybullet or numpy (see constellations' CLIENT_ONLY):
# this module must import nothing heavier than zmq and msgpack.
DEFAULT_COMMAND_PORT = 7700
# Ground truth the viewer needs but team code must not see: published only on loopback.
GROUND_TRUTH_TOPICS = ("poses",)
LOCAL_PORT_OFFSET = 2  # the loopback topics port is the command port + this, by default


class SimClient(CommandAPI):
    """A connection to one drcsim server: requests on the command channel, topics by SUB."""

    def __init__(
        self,
        host: str,
        command_port: int = DEFAULT_COMMAND_PORT,
        publish_port: int | None = None,
        timeout_s: float = 5.0,
        source: str | None = None,
    ) -> None:
        self.host = host
        self.command_port = command_port
        self.publish_port = publish_port  # None: ask the server (hello) on first subscribe
        self.timeout_s = timeout_s
        self.source = source
        self.context = zmq.Context()
        self._ids = itertools.count(1)
        self.commands = self._connect_commands()
        self.topics: zmq.Socket | None = None

    def _endpoint(self, port: int) -> str:
        # "tcp://SOURCE:0;HOST:PORT" makes the connection leave from a chosen local address.
        prefix = f"{self.source}:0;" if self.source else ""
        return f"tcp://{prefix}{self.host}:{port}"

    def _connect_commands(self) -> zmq.Socket:
        sock = self.context.socket(zmq.DEALER)
        sock.linger = 0
        sock.connect(self._endpoint(self.command_port))
        return sock

    # -- commands -----------------------------------------------------------------------------
    def request(self, message: dict[str, Any], timeout_s: float | None = None) -> dict[str, Any]:
        """Send one command and return the server's reply; raise ClientError on timeout."""
        request_id = next(self._ids)
        self.commands.send(msgpack.packb({**message, "id": request_id}, use_bin_type=True))
        deadline = time.monotonic() + (timeout_s if timeout_s is not None else self.timeout_s)
        while True:
            remaining_ms = int((deadline - time.monotonic()) * 1000)
            if remaining_ms <= 0 or not self.commands.poll(remaining_ms):
                # Drop whatever is queued so a late reply cannot answer the next request.
                self.commands.close(linger=0)
                self.commands = self._connect_commands()
                raise ClientError(
                    f"no reply from {self.host}:{self.command_port} "
                    "(server down, or this address is not allowed)"
                )
            reply: dict[str, Any] = msgpack.unpackb(self.commands.recv(), raw=False)
            if reply.get("id") == request_id:
                return reply

    def send_raw(self, frames: list[bytes], timeout_s: float | None = None) -> dict[str, Any]:
        """Send arbitrary frames (for testing the server's defences) and return the reply."""
        self.commands.send_multipart(frames)
        if not self.commands.poll(int((timeout_s or self.timeout_s) * 1000)):
            raise ClientError("no reply to a raw message")
        reply: dict[str, Any] = msgpack.unpackb(self.commands.recv(), raw=False)
        return reply

    # -- topics -------------------------------------------------------------------------------
    def subscribe(self, *topics: str) -> None:
        """Start receiving `topics` (sensors are only computed while someone subscribes)."""
        hidden = [t for t in topics if t in GROUND_TRUTH_TOPICS]
        if hidden:
            raise ClientError(
                f"{', '.join(hidden)} is ground truth: the server publishes it only on the sim "
                "machine's loopback (drcsim watch there), never to the LAN"
            )
        if self.topics is None:
            if self.publish_port is None:
                self.publish_port = int(self.hello()["publish_port"])
            self.topics = self.context.socket(zmq.SUB)
            self.topics.linger = 0
            self.topics.connect(self._endpoint(self.publish_port))
        for topic in topics:
            self.topics.setsockopt(zmq.SUBSCRIBE, topic.encode())

    def unsubscribe(self, *topics: str) -> None:
        """Stop receiving `topics`."""
        if self.topics is not None:
            for topic in topics:
                self.topics.setsockopt(zmq.UNSUBSCRIBE, topic.encode())

    def receive(self, timeout_s: float = 1.0) -> tuple[str, dict[str, Any]] | None:
        """Return the next (topic, message), or None if nothing came within the timeout."""
        if self.topics is None or not self.topics.poll(int(timeout_s * 1000)):
            return None
        topic, payload = self.topics.recv_multipart()
        return topic.decode(), msgpack.unpackb(payload, raw=False)

    def wait_for(
        self,
        topic: str,
        predicate: Callable[[dict[str, Any]], bool] = lambda m: True,
        timeout_s: float = 10.0,
    ) -> dict[str, Any]:
        """Return the first message on `topic` satisfying `predicate`; raise on timeout."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            received = self.receive(max(0.0, deadline - time.monotonic()))
            if received is not None and received[0] == topic and predicate(received[1]):
                return received[1]
        raise ClientError(f"no {topic} message within {timeout_s} s")

    def close(self) -> None:
        """Close the connection."""
        self.commands.close(linger=0)
        if self.topics is not None:
            self.topics.close(linger=0)
        self.context.term()

    def __enter__(self) -> SimClient:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()
