"""Test traffic, run ON the hosts with their python3: `recv` counts UDP, `send` sends it.

recv PORT TIMEOUT IDLE      -> prints {"datagrams": n, "bytes": n} once IDLE seconds pass
                               without a datagram after the first one (or TIMEOUT overall)
send HOST PORT COUNT SIZE [PPS] -> sends COUNT datagrams of SIZE payload bytes
echo PORT TIMEOUT           -> sends every datagram back, until TIMEOUT seconds of silence
probe HOST PORT COUNT INTERVAL -> prints {"rtts_ms": [...], "lost": n} of PROBE_BYTES echoes
"""

import json
import select
import socket
import struct
import sys
import time

PROBE_BYTES = 32


def receive(port: int, timeout: float, idle: float) -> None:
    """Count UDP datagrams and payload bytes arriving on a port."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
        sock.bind(("0.0.0.0", port))  # noqa: S104 - inside a test host's namespace
        print("listening", flush=True)
        datagrams = size = 0
        deadline = time.monotonic() + timeout
        while True:
            wait = deadline - time.monotonic()
            if wait <= 0:
                break
            sock.settimeout(wait)
            try:
                data = sock.recv(65535)
            except TimeoutError:
                break
            datagrams += 1
            size += len(data)
            deadline = time.monotonic() + idle
        print(json.dumps({"datagrams": datagrams, "bytes": size}), flush=True)


def send(host: str, port: int, count: int, size: int, rate: float) -> None:
    """Send datagrams, paced at `rate` a second (0 = as fast as possible)."""
    payload = b"x" * size
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        started = time.monotonic()
        for index in range(count):
            sock.sendto(payload, (host, port))
            if rate:
                pause = started + (index + 1) / rate - time.monotonic()
                if pause > 0:
                    time.sleep(pause)


def echo(port: int, timeout: float) -> None:
    """Send every datagram back to where it came from."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("0.0.0.0", port))  # noqa: S104 - inside a test host's namespace
        sock.settimeout(timeout)
        print("listening", flush=True)
        try:
            while True:
                data, peer = sock.recvfrom(65535)
                sock.sendto(data, peer)
        except TimeoutError:
            return


def probe(host: str, port: int, count: int, interval: float) -> None:
    """Measure round trips of numbered datagrams to an echo, with a microsecond clock."""
    sent: dict[int, float] = {}
    rtts: list[float] = []
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.connect((host, port))
        started = time.perf_counter()
        next_send, index = started, 0
        end = started + count * interval + 3.0
        while time.perf_counter() < end and len(rtts) < count:
            now = time.perf_counter()
            if index < count and now >= next_send:
                sent[index] = now
                sock.send(struct.pack("!I", index).ljust(PROBE_BYTES, b"p"))
                index += 1
                next_send = started + index * interval
                continue
            wait = max(0.0, min(next_send if index < count else end, end) - now)
            ready, _, _ = select.select([sock], [], [], wait)
            if ready:
                data = sock.recv(65535)
                arrived = time.perf_counter()
                (number,) = struct.unpack_from("!I", data)
                rtts.append(1000 * (arrived - sent[number]))
    print(json.dumps({"rtts_ms": rtts, "lost": count - len(rtts)}), flush=True)


if __name__ == "__main__":
    if sys.argv[1] == "recv":
        receive(int(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4]))
    elif sys.argv[1] == "echo":
        echo(int(sys.argv[2]), float(sys.argv[3]))
    elif sys.argv[1] == "probe":
        probe(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), float(sys.argv[5]))
    else:
        rate = float(sys.argv[6]) if len(sys.argv) > 6 else 0.0
        send(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5]), rate)
