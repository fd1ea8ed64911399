"""A TCP relay from an address inside a network namespace to a port on this host's loopback:
hosts on the local provider's public network reach a server the test runs on 127.0.0.1."""

from __future__ import annotations

import ctypes
import os
import socket
import threading
from collections.abc import Iterator
from contextlib import contextmanager

CLONE_NEWNET = 0x40000000


def _listen_in(namespace: str, address: tuple[str, int]) -> socket.socket:
    """Return a listening socket made inside the namespace (a thread of its own enters it:
    the socket keeps the namespace, the rest of the process stays where it is)."""
    made: list[socket.socket | BaseException] = []

    def enter() -> None:
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            fd = os.open(f"/run/netns/{namespace}", os.O_RDONLY)
            try:
                if libc.setns(fd, CLONE_NEWNET) != 0:
                    raise OSError(ctypes.get_errno(), f"setns into {namespace}")
            finally:
                os.close(fd)
            listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            listener.bind(address)
            listener.listen(16)
            made.append(listener)
        except BaseException as exc:  # handed to the caller's thread
            made.append(exc)

    thread = threading.Thread(target=enter)
    thread.start()
    thread.join()
    if isinstance(made[0], BaseException):
        raise made[0]
    return made[0]


def _pump(source: socket.socket, sink: socket.socket) -> None:
    try:
        while data := source.recv(65536):
            sink.sendall(data)
    except OSError:
        pass
    finally:
        for end in (source, sink):
            try:
                end.shutdown(socket.SHUT_RDWR)  # the other direction's pump ends too
            except OSError:
                pass
        source.close()  # each pump closes the socket it reads: both get closed


@contextmanager
def relay(namespace: str, address: tuple[str, int], target_port: int) -> Iterator[None]:
    """Relay connections to `address` inside `namespace` to 127.0.0.1:target_port."""
    listener = _listen_in(namespace, address)
    listener.settimeout(0.5)
    stop = threading.Event()

    def serve() -> None:
        while not stop.is_set():
            try:
                inbound, _ = listener.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            inbound.settimeout(None)
            outbound = socket.create_connection(("127.0.0.1", target_port))
            for ends in ((inbound, outbound), (outbound, inbound)):
                threading.Thread(target=_pump, args=ends, daemon=True).start()

    server = threading.Thread(target=serve, daemon=True)
    server.start()
    try:
        yield
    finally:
        stop.set()
        server.join(5)
        listener.close()
