"""`csrouter serve`: bind the two queues, run the packet loop, answer control requests."""

from __future__ import annotations

import logging
import os
import select
import signal
import socket
import warnings
from collections.abc import Callable
from types import FrameType
from typing import Any

from netfilterqueue import COPY_PACKET, NetfilterQueue

from csrouter.config import RouterConfig, check_cap, check_latency
from csrouter.control import ControlServer
from csrouter.errors import ConfigError
from csrouter.ocu_path import OcuPath
from csrouter.packets import HEADER_COPY_BYTES
from csrouter.protocol import ARM, COUNTERS, DISARM, STATUS
from csrouter.rules import ensure_rules
from csrouter.run import DOWNLINK, UPLINK

log = logging.getLogger("csrouter")
SOCKET_BUFFER_BYTES = 8 * 1024 * 1024
# above ordinary processes, so a busy machine does not add its scheduling delay to the latency
REALTIME_PRIORITY = 20


def serve(config: RouterConfig) -> int:
    """Run the daemon until SIGTERM/SIGINT; return the exit status."""
    path = OcuPath(config)
    _realtime()
    for added in ensure_rules(config):
        log.warning("added missing rule: iptables -t mangle %s", added)
    queues = {
        UPLINK: _bind(config.uplink_queue, config.queue_max_packets, path, UPLINK),
        DOWNLINK: _bind(config.downlink_queue, config.queue_max_packets, path, DOWNLINK),
    }
    server = ControlServer(config.socket, _handler(path))
    server.start()
    signal.signal(signal.SIGTERM, _stop(path))
    signal.signal(signal.SIGINT, _stop(path))
    log.info(
        "serving queues %d (uplink) and %d (downlink)", config.uplink_queue, config.downlink_queue
    )
    _notify("READY=1")
    try:
        _loop(path, list(queues.values()))
    finally:
        server.close()
        for queue in queues.values():
            queue.unbind()
        path.save_on_exit()
    log.info("stopped; %d packets dropped while stopping", path.dropped_while_stopping)
    return 0


def _realtime() -> None:
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(REALTIME_PRIORITY))
    except OSError as exc:
        log.warning("no real-time priority (%s): the latency may jitter under load", exc)


def _bind(number: int, max_len: int, path: OcuPath, direction: str) -> NetfilterQueue:
    queue = NetfilterQueue()

    def on_packet(packet: Any) -> None:
        path.on_packet(direction, packet)

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        queue.bind(
            number,
            on_packet,
            max_len=max_len,
            mode=COPY_PACKET,
            range=HEADER_COPY_BYTES,
            sock_len=SOCKET_BUFFER_BYTES,
        )
    for warning in caught:
        log.warning("queue %d: %s", number, warning.message)
    return queue


def _loop(path: OcuPath, queues: list[NetfilterQueue]) -> None:
    by_fd = {queue.get_fd(): queue for queue in queues}
    while True:
        timeout = path.service()
        if path.stopping and path.held() == 0:
            return
        try:
            ready, _, _ = select.select(list(by_fd), [], [], timeout)
        except InterruptedError:
            continue
        for fd in ready:
            by_fd[fd].run(block=False)


def _stop(path: OcuPath) -> Callable[[int, FrameType | None], None]:
    def handle(signum: int, frame: FrameType | None) -> None:
        # held packets still leave on time; new ones are dropped, never let through early
        path.stopping = True

    return handle


def _handler(path: OcuPath) -> Callable[[dict[str, Any]], dict[str, Any]]:
    def handle(request: dict[str, Any]) -> dict[str, Any]:
        op = request.get("op")
        if op == ARM:
            return path.arm(
                check_latency(request["latency_ms"]),
                check_cap("uplink_bits", request.get("uplink_bits")),
                check_cap("downlink_bits", request.get("downlink_bits")),
                _run_id(request.get("run_id")),
            )
        if op == DISARM:
            return path.disarm()
        if op == COUNTERS:
            return path.counters()
        if op == STATUS:
            return path.status()
        raise ConfigError(f"unknown request {op!r}")

    return handle


def _run_id(value: Any) -> str | None:
    if value is None:
        return None
    if not isinstance(value, str) or not 0 < len(value) <= 128 or not value.isprintable():
        raise ConfigError("run_id must be 1-128 printable characters")
    return value


def _notify(message: str) -> None:
    """Tell systemd (Type=notify) how the daemon is doing; nothing without systemd."""
    address = os.environ.get("NOTIFY_SOCKET")
    if not address:
        return
    if address.startswith("@"):
        address = "\0" + address[1:]
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as notify:
        notify.connect(address)
        notify.sendall(message.encode())
