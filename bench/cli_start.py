"""Benchmark the command line's start: a few commands against `python -c pass`, same run.

Run: `.venv/bin/python -m bench.cli_start [--rounds 5]`. Each command runs in a fresh process;
the figure is the median wall time and CPU time (user + system) of the rounds. Commands that
need the database get a throw-away instance folder (migrated once before timing).
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

COMMANDS = [
    ["--help"],
    ["--version"],
    ["user", "--help"],
    ["team", "list"],
    ["leaderboard"],
]


def timed(argv: list[str], env: dict[str, str]) -> tuple[float, float]:
    """Run argv once; return its wall and CPU seconds."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run(argv, env=env, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def median_of(argv: list[str], env: dict[str, str], rounds: int) -> tuple[float, float]:
    """Return the median wall and CPU seconds of `rounds` runs."""
    runs = [timed(argv, env) for _ in range(rounds)]
    return statistics.median(w for w, _ in runs), statistics.median(c for _, c in runs)


def line(wall: float, cpu: float) -> str:
    """Return a figure's columns."""
    return f"wall {wall * 1000:7.0f} ms  cpu {cpu * 1000:6.0f} ms"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    cloudsim = str(Path(sys.executable).with_name("cloudsim"))
    with tempfile.TemporaryDirectory() as folder:
        env = dict(os.environ, CLOUDSIM_INSTANCE_DIR=folder, CLOUDSIM_LOG_LEVEL="WARNING")
        subprocess.run([cloudsim, "db", "upgrade"], env=env, check=True, capture_output=True)
        print(f"load before: {os.getloadavg()[0]:.2f}")
        ref_wall, ref_cpu = median_of([sys.executable, "-c", "pass"], env, args.rounds)
        print(
            f"{'python -c pass':<24} wall {ref_wall * 1000:7.0f} ms  cpu {ref_cpu * 1000:6.0f} ms"
        )
        for command in COMMANDS:
            wall, cpu = median_of([cloudsim, *command], env, args.rounds)
            name = "cloudsim " + " ".join(command)
            ratios = f"x{wall / ref_wall:.1f} wall, x{cpu / max(ref_cpu, 1e-3):.1f} cpu"
            print(f"{name:<24} {line(wall, cpu)}  ({ratios} of the reference)")
        print(f"load after: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
