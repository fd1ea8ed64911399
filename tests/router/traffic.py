"""Test traffic, run ON the hosts with their python3: `recv` counts UDP, `send` sends it.

recv PORT TIMEOUT IDLE      -> prints {"datagrams": n, "bytes": n} once IDLE seconds pass
                               without a datagram after the first one (or TIMEOUT overall)
send HOST PORT COUNT SIZE [PPS] -> sends COUNT datagrams of SIZE payload bytes
"""

import json
import socket
import sys
import time


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


if __name__ == "__main__":
    if sys.argv[1] == "recv":
        receive(int(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4]))
    else:
        rate = float(sys.argv[6]) if len(sys.argv) > 6 else 0.0
        send(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5]), rate)
