"""`drcsim ladder`: every reference controller over every world and configuration.

Each run is a real `drcsim serve --lockstep` process driven over loopback by the
controller, as a team would run it; runs go in parallel, one per core.
"""

from __future__ import annotations

import os
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from drcsim.bench import start_server, wait_ready
from drcsim.client import SimClient
from drcsim.controllers import CONTROLLERS
from drcsim.errors import ClientError
from drcsim.worlds import CONFIG_NAMES, WORLD_NAMES


def run_one(style: str, world: str, config: str, time_limit_s: float) -> dict[str, Any]:
    """Run controller `style` on one world and configuration; return its score row."""
    started = time.monotonic()
    process, port = start_server(world, config, ["--lockstep", "--time-limit", str(time_limit_s)])
    try:
        wait_ready(port, process)
        with SimClient("127.0.0.1", port, timeout_s=30.0) as client:
            controller = CONTROLLERS[style](client, timeout_s=3600.0)
            try:
                score = controller.run()
                note = controller.gave_up  # down after a fall it does not get up from
            except ClientError as exc:  # the controller gave up (a refused command)
                note, score = str(exc), {}
            if not score.get("ended"):
                try:
                    client.stop()
                except ClientError:
                    pass  # it ended (falls, time limit) after the controller's last look
                score = dict(client.state()["score"])
    finally:
        if process.poll() is None:
            process.terminate()
        process.wait(timeout=60)
    return {
        "controller": style,
        "world": world,
        "config": config,
        "checkpoints": int(score["checkpoints"]),
        "falls": int(score["falls"]),
        "reason": score.get("reason"),
        "gave_up": note,
        "wall_s": round(time.monotonic() - started, 1),
    }


def run_ladder(
    styles: list[str] | None = None,
    worlds: list[str] | None = None,
    configs: list[str] | None = None,
    time_limit_s: float = 600.0,
    jobs: int | None = None,
) -> dict[str, Any]:
    """Run every (controller, world, config); return the rows and the totals per controller."""
    styles = styles or list(CONTROLLERS)
    worlds = worlds or list(WORLD_NAMES)
    configs = configs or list(CONFIG_NAMES)
    work = [(s, w, c) for s in styles for w in worlds for c in configs]
    jobs = jobs or max(1, os.cpu_count() or 1)
    started = time.monotonic()
    with ThreadPoolExecutor(max_workers=jobs) as pool:
        rows = list(pool.map(lambda item: run_one(item[0], item[1], item[2], time_limit_s), work))
    totals = {
        style: {
            "checkpoints": sum(r["checkpoints"] for r in rows if r["controller"] == style),
            "of": 4 * sum(1 for r in rows if r["controller"] == style),
            "falls": sum(r["falls"] for r in rows if r["controller"] == style),
        }
        for style in styles
    }
    return {
        "runs": rows,
        "totals": totals,
        "jobs": jobs,
        "time_limit_s": time_limit_s,
        "wall_s": round(time.monotonic() - started, 1),
    }
