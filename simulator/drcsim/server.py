"""The network API on the sim machine: ZeroMQ + msgpack topics, command channel, lock-step."""

from __future__ import annotations

import ipaddress
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import zmq

from drcsim.client import GROUND_TRUTH_TOPICS, LOCAL_PORT_OFFSET
from drcsim.engine import Simulation
from drcsim.errors import ProtocolError
from drcsim.models.humanoid import ALL_JOINTS
from drcsim.protocol import BEHAVIOURS, MAX_MESSAGE_BYTES, RANGES, decode_command, encode
from drcsim.ratelimit import RateLimiter
from drcsim.rundir import LIVE_EVERY_S, write_live
from drcsim.scene import TIMESTEP
from drcsim.sensors import SENSOR_TOPICS

log = logging.getLogger("drcsim.server")
ZAP_ENDPOINT = "inproc://zeromq.zap.01"
ZAP_DOMAIN = b"drcsim"
LAN_ON_DEMAND_TOPICS = (*SENSOR_TOPICS, "robot_state")  # for team code, on the LAN
ALWAYS_TOPICS = ("clock", "score")
LOCAL_TOPICS = (*GROUND_TRUTH_TOPICS, *ALWAYS_TOPICS)  # what the loopback socket carries
LOOPBACK = "127.0.0.1"
MAX_LAG_STEPS = 200  # beyond this the wall clock is re-anchored: the run is slower than real time
BATCH_STEPS = 5  # physics steps between looks at the sockets in real-time mode
# Commands read per look: enough that a flood reaches the rate limiter (and is dropped there,
# a few microseconds each) instead of queueing in front of everyone else's.
READ_PER_LOOK = 200


@dataclass
class ServerSettings:
    """Where to listen, who may connect and how time advances."""

    bind: str = "127.0.0.1"
    command_port: int = 7700
    publish_port: int = 7701
    local_port: int = 7700 + LOCAL_PORT_OFFSET  # ground truth, on the sim machine's loopback only
    allow: list[str] = field(default_factory=lambda: ["127.0.0.1/32"])
    lockstep: bool = False
    linger_s: float = 1.0  # keep answering this long after the run ends


def parse_networks(entries: list[str]) -> list[ipaddress.IPv4Network | ipaddress.IPv6Network]:
    """Return the allow-list as networks (single addresses become /32 or /128)."""
    try:
        return [ipaddress.ip_network(entry, strict=False) for entry in entries]
    except ValueError as exc:
        raise ProtocolError(f"bad allow-list entry: {exc}") from exc


def _wanted(prefixes: set[bytes], topics: tuple[str, ...]) -> set[str]:
    """Return the topics some subscribed prefix matches."""
    return {t for t in topics if any(t.encode().startswith(p) for p in prefixes)}


def describe_run(sim: Simulation, lockstep: bool) -> dict[str, Any]:
    """Return the hello reply: world, joints and limits, behaviours, topics, course briefing."""
    spec = sim.spec
    joints = [
        {
            "name": j.name,
            "lower": j.lower,
            "upper": j.upper,
            "velocity": j.velocity,
            "effort": j.effort,
        }
        for j in ALL_JOINTS
    ]
    return {
        "world": spec.name,
        "config": spec.config,
        "title": spec.title,
        "lockstep": lockstep,
        "timestep": TIMESTEP,
        "time_limit_s": spec.time_limit_s,
        "joints": joints,
        "behaviours": sorted(BEHAVIOURS),
        "ranges": {key: [low, high] for key, (low, high, _) in RANGES.items()},
        "topics": [*ALWAYS_TOPICS, *LAN_ON_DEMAND_TOPICS],
        "local_topics": list(LOCAL_TOPICS),
        "checkpoints": [c["name"] for c in spec.checkpoints],
        "course": sim.briefing,
    }


@dataclass
class ServerStats:
    """Counters a run reports: requests served, rejected messages, refused peers."""

    requests: int = 0
    rejected: int = 0
    refused: int = 0
    dropped: int = 0  # over a peer's budget (real-time mode), neither answered nor logged


class SimServer:
    """Serves one Simulation until its run ends or `stop()` is called."""

    def __init__(self, sim: Simulation, settings: ServerSettings) -> None:
        self.sim = sim
        self.settings = settings
        self.networks = parse_networks(settings.allow)
        self.stats = ServerStats()
        self.limiter = RateLimiter()
        self._rejections: dict[str, tuple[float, int]] = {}  # peer: last logged, not logged
        self.running = True
        self.subscriptions: set[bytes] = set()  # on the LAN-facing socket
        self.local_subscriptions: set[bytes] = set()
        self.context = zmq.Context()
        # The ZAP handler must be bound before any socket accepts a connection.
        self.zap = self.context.socket(zmq.REP)
        self.zap.bind(ZAP_ENDPOINT)
        self.router = self.context.socket(zmq.ROUTER)
        self.publisher = self.context.socket(zmq.XPUB)
        for sock in (self.router, self.publisher):
            sock.zap_domain = ZAP_DOMAIN
            sock.linger = 0
            sock.setsockopt(zmq.MAXMSGSIZE, 4 * MAX_MESSAGE_BYTES)
        self.publisher.sndhwm = 200  # a slow subscriber loses old sensor frames, not the run
        self.router.bind(f"tcp://{settings.bind}:{settings.command_port}")
        self.publisher.bind(f"tcp://{settings.bind}:{settings.publish_port}")
        # Ground truth (every body's pose) must not reach team code on the field computers:
        # it goes out only here, on loopback, where just the sim machine's own processes (the
        # viewer's relay) connect. No ZAP domain: the allow-list names the LAN, not loopback.
        self.local = self.context.socket(zmq.XPUB)
        self.local.linger = 0
        self.local.sndhwm = 200
        self.local.bind(f"tcp://{LOOPBACK}:{settings.local_port}")
        self.poller = zmq.Poller()
        for sock in (self.zap, self.router, self.publisher, self.local):
            self.poller.register(sock, zmq.POLLIN)
        sim.options.publish = self.publish
        self._rtf_mark = (time.monotonic(), sim.step_count)
        self.rtf = 0.0
        self._live_at = 0.0

    # -- publishing ---------------------------------------------------------------------------
    def publish(self, topic: str, message: dict[str, Any]) -> None:
        """Send one message on a topic."""
        if topic == "clock":
            message["rtf"] = self.rtf
        frames = [topic.encode(), encode(message)]
        if topic not in GROUND_TRUTH_TOPICS:
            self.publisher.send_multipart(frames)
        if topic in LOCAL_TOPICS:
            self.local.send_multipart(frames)

    def _update_rtf(self) -> None:
        now, step = time.monotonic(), self.sim.step_count
        wall = now - self._rtf_mark[0]
        if wall >= 1.0:
            self.rtf = (step - self._rtf_mark[1]) * TIMESTEP / wall
            self._rtf_mark = (now, step)
            self.limiter.settle(now)
        if now - self._live_at >= LIVE_EVERY_S:
            self.write_live()

    def write_live(self) -> None:
        """Publish the run's live figures in its log folder (a supervisor reads them over SSH)."""
        self._live_at = time.monotonic()
        if self.sim.options.log_dir is None:
            return
        figures = {
            "sim_time": round(self.sim.sim_time, 3),
            "rtf": round(self.rtf, 3),
            "score": self.sim.scorer.reached,
            "falls": self.sim.scorer.falls,
            "ended": self.sim.ended,
            "wall_time": round(time.time(), 3),
        }
        try:
            write_live(Path(self.sim.options.log_dir), figures)
        except OSError as exc:  # the run goes on; only its live view goes stale
            log.warning("cannot write the live figures: %s", exc)

    # -- sockets ------------------------------------------------------------------------------
    def _handle_zap(self) -> None:
        frames = self.zap.recv_multipart()
        version, request_id, _domain, address = frames[:4]
        allowed = False
        try:
            peer = ipaddress.ip_address(address.decode())
            allowed = any(peer in network for network in self.networks)
        except ValueError:
            allowed = False
        if not allowed:
            self.stats.refused += 1
            log.warning("refused connection from %s (not in the allow-list)", address.decode())
        status = (b"200", b"OK") if allowed else (b"400", b"address not allowed")
        self.zap.send_multipart([version, request_id, *status, b"", b""])

    def _handle_subscription(self, sock: zmq.Socket) -> None:
        frame = sock.recv()
        if not frame:
            return
        topic, local = frame[1:], sock is self.local
        subscriptions = self.local_subscriptions if local else self.subscriptions
        if frame[0] == 1:
            subscriptions.add(topic)
            if not local and topic and _wanted({topic}, GROUND_TRUTH_TOPICS):
                # it gets nothing there; say why (an empty prefix is a plain "everything")
                self.stats.rejected += 1
                log.warning(
                    "refused a subscription to %r on the LAN: ground truth (%s) is published "
                    "only on the sim machine's loopback",
                    topic.decode(errors="replace"),
                    ", ".join(GROUND_TRUTH_TOPICS),
                )
        else:
            subscriptions.discard(topic)
        self.sim.active_topics = _wanted(self.subscriptions, LAN_ON_DEMAND_TOPICS) | _wanted(
            self.local_subscriptions, GROUND_TRUTH_TOPICS
        )

    def _handle_commands(self) -> None:
        for _ in range(READ_PER_LOOK):
            try:
                frames = self.router.recv_multipart(zmq.NOBLOCK, copy=False)
            except zmq.Again:
                return
            self._handle_command(frames)

    def _handle_command(self, frames: list[zmq.Frame]) -> None:
        identity = frames[0].bytes
        peer = str(frames[-1].get("Peer-Address")) if len(frames) > 1 else "?"
        # Real time is the run's: a flooding peer's excess is dropped before any work on it
        # (lock-step time waits for the client, so its pace is its own business).
        if not self.settings.lockstep and not self.limiter.admit(peer, time.monotonic()):
            self.stats.dropped += 1
            return
        if len(frames) != 2:
            self._reject(identity, peer, f"expected one frame, got {len(frames) - 1}")
            return
        try:
            message = decode_command(frames[1].bytes)
        except ProtocolError as exc:
            self._reject(identity, peer, str(exc), exc.request_id)
            return
        self.stats.requests += 1
        reply = self._serve(message, peer)
        if "id" in message:
            reply["id"] = message["id"]
        self.router.send_multipart([identity, encode(reply)])

    def _reject(
        self, identity: bytes, peer: str, reason: str, request_id: int | None = None
    ) -> None:
        self.stats.rejected += 1
        # One line a second per peer at most: a stream of bad frames must not become a
        # stream of log lines (the count of those not logged goes in the next line).
        now = time.monotonic()
        logged_at, unlogged = self._rejections.get(peer, (-1.0, 0))
        if self.limiter.flooding(peer) or now - logged_at < 1.0:
            self._rejections[peer] = (logged_at, unlogged + 1)
        else:
            more = f" ({unlogged} more rejected since, not logged)" if unlogged else ""
            log.warning("rejected message from %s: %s%s", peer, reason, more)
            self._rejections[peer] = (now, 0)
        reply: dict[str, Any] = {"ok": False, "error": reason}
        if request_id is not None:
            reply["id"] = request_id
        self.router.send_multipart([identity, encode(reply)])

    def _serve(self, message: dict[str, Any], peer: str) -> dict[str, Any]:
        op = message["op"]
        if op == "hello":
            return {"ok": True, **self.describe()}
        if op in ("state", "step"):
            if op == "step":
                if not self.settings.lockstep:
                    return {"ok": False, "error": "step is only accepted in lock-step mode"}
                self.sim.step(message["steps"])
            snapshot = self.sim.snapshot()
            if self.sim.recorder is not None:  # the estimate as the team received it
                self.sim.recorder.team("robot_state", self.sim.sim_time, snapshot)
            return {"ok": True, "state": snapshot}
        return self.sim.apply_command(message, source=peer)

    def describe(self) -> dict[str, Any]:
        """Return what a client needs to know about this run (the hello reply)."""
        return {
            **describe_run(self.sim, self.settings.lockstep),
            "publish_port": self.settings.publish_port,
            "local_port": self.settings.local_port,
        }

    def _drain(self, timeout_ms: int) -> None:
        for sock, _ in self.poller.poll(timeout_ms):
            if sock is self.zap:
                self._handle_zap()
            elif sock is self.router:
                self._handle_commands()
            else:
                self._handle_subscription(sock)

    # -- main loop ----------------------------------------------------------------------------
    def run(self, should_stop: Callable[[], bool] = lambda: False) -> None:
        """Serve until the run ends (plus the linger time), `stop()` or `should_stop()`."""
        anchor_time, anchor_step = time.monotonic(), self.sim.step_count
        ended_at: float | None = None
        while self.running and not should_stop():
            now = time.monotonic()
            if self.sim.ended:
                if ended_at is None:
                    self.write_live()
                ended_at = ended_at or now
                if now - ended_at >= self.settings.linger_s:
                    break
                self._drain(10)
                continue
            if self.settings.lockstep:
                self._drain(10)
                continue
            due = anchor_step + int((now - anchor_time) / TIMESTEP) - self.sim.step_count
            if due > MAX_LAG_STEPS:
                anchor_time, anchor_step = now, self.sim.step_count
                due = 1
            if due > 0:
                self.sim.step(min(due, BATCH_STEPS))
                self._update_rtf()
                self._drain(0)
            else:
                self._drain(1)

    def stop(self) -> None:
        """Ask the loop to finish."""
        self.running = False

    def close(self) -> None:
        """Close the sockets and the simulation (which finalises its logs)."""
        self.limiter.settle(time.monotonic(), final=True)
        self.sim.close()
        for sock in (self.router, self.publisher, self.local, self.zap):
            sock.close(linger=0)
        self.context.term()
