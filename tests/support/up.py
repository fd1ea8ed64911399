"""`cloudsim up` as a user starts it, on free ports with its own instance folder."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from tests.support.servers import free_port, wait_for
from tests.support.workers import kill_worker_tree


@dataclass(frozen=True)
class Up:
    """A running `cloudsim up`: where it serves, its environment, its terminal output."""

    address: str
    env: dict[str, str]
    log: Path
    process: subprocess.Popen[bytes]

    def crash(self) -> None:
        """SIGKILL the whole tree (web, worker, beat, Redis), as a power cut would."""
        kill_worker_tree(self.process)


@contextmanager
def cloudsim_up(tmp_path: Path, root: Path, **settings: str) -> Iterator[Up]:
    """Run `cloudsim up` (one worker slot, admin root@example.org, CLOUDSIM_* settings added
    or replacing these) until the block ends, then stop it with Ctrl-C and check it exits
    cleanly (unless the block crashed it). Run again on the same tmp_path, it finds its
    instance folder as it was left."""
    address = f"127.0.0.1:{free_port()}"
    env = dict(
        os.environ,
        CLOUDSIM_INSTANCE_DIR=str(tmp_path / "instance"),
        CLOUDSIM_BIND=address,
        CLOUDSIM_REDIS_PORT=str(free_port()),
        CLOUDSIM_WORKER_CONCURRENCY="1",
        CLOUDSIM_ADMIN_EMAIL="root@example.org",
    )
    env.update(settings)
    env.pop("CLOUDSIM_REDIS_URL", None)  # its own Redis, as `make run` starts it
    log = tmp_path / "up.log"
    with log.open("wb") as out:
        process = subprocess.Popen(
            [sys.executable, "-m", "cloudsim.cli", "up"],
            env=env,
            cwd=root,
            stdout=out,
            stderr=subprocess.STDOUT,
        )
    try:
        wait_for(lambda: "CloudSim is running at" in log.read_text(), 240, "cloudsim up")
        yield Up(address, env, log, process)
    finally:
        if process.poll() is None:  # not crashed on purpose: stopped as a user stops it
            process.send_signal(signal.SIGINT)
            assert process.wait(60) == 0
