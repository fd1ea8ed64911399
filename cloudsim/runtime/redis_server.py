"""A private Redis server, for when no CLOUDSIM_REDIS_URL is configured."""

from __future__ import annotations

import shutil
from pathlib import Path


class RedisUnavailable(Exception):
    """redis-server is not installed."""


def redis_command(port: int, data_dir: Path) -> list[str]:
    """Return the argv of a loopback-only redis-server keeping an append-only log in data_dir."""
    binary = shutil.which("redis-server")
    if binary is None:
        raise RedisUnavailable("redis-server is not installed (Debian package redis-server)")
    data_dir.mkdir(parents=True, exist_ok=True)
    return [
        binary,
        "--port",
        str(port),
        "--bind",
        "127.0.0.1",
        "--protected-mode",
        "yes",
        "--dir",
        str(data_dir),
        # Queued jobs survive a restart of Redis: append-only file, fsync every second.
        "--appendonly",
        "yes",
        "--appendfsync",
        "everysec",
        "--save",
        "",
        "--daemonize",
        "no",
        "--loglevel",
        "warning",
    ]
