"""An in-process stand-in for SimClient: the same calls straight on a Simulation, lock-step."""

from __future__ import annotations

from typing import Any

from drcsim.engine import Simulation
from drcsim.errors import ClientError
from drcsim.protocol import check_command
from drcsim.server import describe_run


class LocalClient:
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

    def _checked(self, message: dict[str, Any]) -> dict[str, Any]:
        reply = self.request(message)
        if not reply.get("ok"):
            raise ClientError(f"{message.get('op')} refused: {reply.get('error')}")
        return reply

    def hello(self) -> dict[str, Any]:
        """Return the run's description."""
        return self._checked({"op": "hello"})

    def state(self) -> dict[str, Any]:
        """Return the robot's current state."""
        state: dict[str, Any] = self._checked({"op": "state"})["state"]
        return state

    def step(self, steps: int = 1) -> dict[str, Any]:
        """Advance by `steps` physics steps; return the state after them."""
        state: dict[str, Any] = self._checked({"op": "step", "steps": steps})["state"]
        return state

    def joints(
        self,
        position: dict[str, float] | None = None,
        torque: dict[str, float] | None = None,
        gains: dict[str, list[float]] | None = None,
    ) -> dict[str, Any]:
        """Command joints."""
        message: dict[str, Any] = {"op": "joints"}
        for key, value in (("position", position), ("torque", torque), ("gains", gains)):
            if value:
                message[key] = value
        return self._checked(message)

    def behaviour(self, name: str, **params: Any) -> dict[str, Any]:
        """Start a behaviour; raise ClientError if refused."""
        return self._checked({"op": "behaviour", "name": name, **params})

    def try_behaviour(self, name: str, **params: Any) -> dict[str, Any]:
        """Start a behaviour and return the reply even if refused."""
        return self.request({"op": "behaviour", "name": name, **params})

    def stop(self) -> dict[str, Any]:
        """End the run."""
        return self._checked({"op": "stop"})
