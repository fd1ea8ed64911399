"""Fixtures for the simulator tests: in-process simulations and real servers on loopback."""

from __future__ import annotations

import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from drcsim.bench import start_server, wait_ready
from drcsim.engine import RunOptions, Simulation
from drcsim.models import humanoid
from drcsim.protocol import check_command
from drcsim.scene import yaw_quaternion

ServerFactory = Callable[..., tuple[subprocess.Popen[bytes], int]]


@pytest.fixture
def make_sim() -> Iterator[Callable[..., Simulation]]:
    """Return a factory of simulations that are all closed after the test."""
    made: list[Simulation] = []

    def factory(world: str, config: str = "1", **options: object) -> Simulation:
        sim = Simulation(world, config, RunOptions(**options))  # type: ignore[arg-type]
        made.append(sim)
        return sim

    yield factory
    for sim in made:
        sim.close()


def _place(sim: Simulation, x: float, y: float, yaw: float) -> None:
    """Stand the robot at (x, y) facing `yaw`, balanced by the walker, as if it had walked there."""
    client, robot = sim.client, sim.scene.robot
    z = humanoid.STAND_PELVIS_HEIGHT + sim.scene.ground_height(x, y)
    client.resetBasePositionAndOrientation(robot, [x, y, z], yaw_quaternion(yaw))
    client.resetBaseVelocity(robot, [0, 0, 0], [0, 0, 0])
    sim.controller.reset_to(humanoid.STAND_POSTURE)
    assert sim.apply_command(check_command({"op": "behaviour", "name": "stand"}))["ok"]
    sim.step(500)  # settled on its feet


@pytest.fixture
def place() -> Callable[[Simulation, float, float, float], None]:
    """Return a function that stands the robot at a pose, for tests of what it does there.

    The walker walks about 0.24 m/s: tests whose subject is not the walk start where it ends.
    """
    return _place


@pytest.fixture
def server(tmp_path: Path) -> Iterator[ServerFactory]:
    """Start `drcsim serve` processes on free loopback ports; stop them by PID afterwards."""
    processes: list[subprocess.Popen[bytes]] = []

    def factory(
        world: str = "vrc_task_2",
        config: str = "1",
        *extra: str,
        logs: bool = False,
        source: str = "127.0.0.1",
        host: str = "127.0.0.1",
        lockstep: bool = True,
    ) -> tuple[subprocess.Popen[bytes], int]:
        log_dir = tmp_path / f"run-{len(processes)}" if logs else None
        process, port = start_server(
            world,
            config,
            ["--lockstep", *extra] if lockstep else list(extra),
            log_dir,
            stderr=tmp_path / f"server-{len(processes)}.log",
        )
        processes.append(process)
        wait_ready(port, process, source=source, host=host)
        return process, port

    yield factory
    for process in processes:
        if process.poll() is None:
            process.terminate()
        process.wait(timeout=30)
