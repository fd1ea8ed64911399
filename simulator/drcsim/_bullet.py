"""pybullet access that keeps its banners ("pybullet build time", "argv[0]=") off stdout."""

import contextlib
import functools
import os
import sys
from collections.abc import Iterator
from typing import Any


@contextlib.contextmanager
def _stdout_to_stderr() -> Iterator[None]:
    """Point file descriptor 1 at stderr for the duration (C code prints there)."""
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        os.dup2(2, 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


with _stdout_to_stderr():
    import pybullet
    from pybullet_utils.bullet_client import BulletClient


class _BoundClient(BulletClient):
    """A BulletClient that binds each pybullet function to its client once, not at every call.

    BulletClient looks the function up and wraps it in a new partial on every attribute access
    (about 1 µs, tens of thousands of times per simulated second); keeping the partial in the
    instance makes later accesses plain attribute reads.
    """

    def __getattr__(self, name: str) -> Any:
        attribute = super().__getattr__(name)
        if name == "disconnect":
            # The kept partials carry this client's id, which pybullet hands to the next
            # connection: dropped, a closed client raises instead of moving another world.
            for kept in [k for k, v in vars(self).items() if isinstance(v, functools.partial)]:
                delattr(self, kept)
        elif isinstance(attribute, functools.partial):
            setattr(self, name, attribute)
        return attribute


def new_client() -> BulletClient:
    """Return a fresh headless physics client."""
    with _stdout_to_stderr():
        return _BoundClient(connection_mode=pybullet.DIRECT)


__all__ = ["BulletClient", "new_client", "pybullet"]
