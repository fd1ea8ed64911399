"""pybullet access that keeps its banners ("pybullet build time", "argv[0]=") off stdout."""

import contextlib
import os
import sys
from collections.abc import Iterator


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


def new_client() -> BulletClient:
    """Return a fresh headless physics client."""
    with _stdout_to_stderr():
        return BulletClient(connection_mode=pybullet.DIRECT)


__all__ = ["BulletClient", "new_client", "pybullet"]
