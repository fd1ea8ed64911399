"""An in-process stand-in for SimClient: the same calls straight on a Simulation, lock-step."""

from __future__ import annotations

from typing import Any

from drcsim.commands import CommandAPI
from drcsim.engine import Simulation
from drcsim.protocol import check_command
from drcsim.server import describe_run


class LocalClient(CommandAPI):
    """Drives a Simulation in this process exactly as a lock-step SimClient would."""

    def __init__(self, sim: Simulation) -> None:
        self.sim = sim

    def request(self, message: dict[str, Any]) -> dict[str, Any]:
        """Check and apply one command; return the reply a server would send."""
        clean = check_command(message)
        if clean["op"] == "hello":
            return {"ok": True, **describe_run(self.sim, lockstep=True)}
        if clean["op"] == "state":
            return {"ok": True, "state": self.sim.snapshot()}
        if clean["op"] == "step":
            self.sim.step(clean["steps"])
            return {"ok": True, "state": self.sim.snapshot()}
        return self.sim.apply_command(clean)
