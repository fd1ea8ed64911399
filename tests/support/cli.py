"""Run `cloudsim` commands in-process against a database of their own, as a user's shell would."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from click.testing import CliRunner, Result

from cloudsim.cli import main


def migrated_cli(
    instance_dir: Path, redis_url: str, encryption_key: str, **settings: str
) -> Callable[..., Result]:
    """Return a runner of `cloudsim ARGS` on a new, migrated instance folder (CLOUDSIM_*
    settings added)."""
    env = {
        "CLOUDSIM_INSTANCE_DIR": str(instance_dir),
        "CLOUDSIM_REDIS_URL": redis_url,  # a broker, but no worker behind it
        "CLOUDSIM_ENCRYPTION_KEYS": encryption_key,
        **settings,
    }

    def invoke(*args: str) -> Result:
        return CliRunner().invoke(main, list(args), env=env)

    migrated = invoke("db", "upgrade")
    assert migrated.exit_code == 0, migrated.output
    return invoke
