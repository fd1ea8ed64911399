"""The commands a run speaks, once: SimClient (over the network) and LocalClient (in process)."""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

from drcsim.errors import ClientError


class CommandAPI(ABC):
    """hello, state, step, joints, behaviour and stop, over whatever `request` sends them to."""

    @abstractmethod
    def request(self, message: dict[str, Any]) -> dict[str, Any]:
        """Send one command and return the reply."""

    def _checked(self, message: dict[str, Any]) -> dict[str, Any]:
        reply = self.request(message)
        if not reply.get("ok"):
            raise ClientError(f"{message.get('op')} refused: {reply.get('error')}")
        return reply

    def hello(self) -> dict[str, Any]:
        """Return the run's description: world, joints, behaviours, topics, course."""
        return self._checked({"op": "hello"})

    def state(self) -> dict[str, Any]:
        """Return the robot's current state."""
        state: dict[str, Any] = self._checked({"op": "state"})["state"]
        return state

    def step(self, steps: int = 1) -> dict[str, Any]:
        """Advance a lock-step run by `steps` physics steps; return the state after them."""
        state: dict[str, Any] = self._checked({"op": "step", "steps": steps})["state"]
        return state

    def joints(
        self,
        position: dict[str, float] | None = None,
        torque: dict[str, float] | None = None,
        gains: dict[str, list[float]] | None = None,
    ) -> dict[str, Any]:
        """Command joints: PID position targets, direct torques and/or gains."""
        message: dict[str, Any] = {"op": "joints"}
        for key, value in (("position", position), ("torque", torque), ("gains", gains)):
            if value:
                message[key] = value
        return self._checked(message)

    def behaviour(self, name: str, **params: Any) -> dict[str, Any]:
        """Start a behaviour (see README): stand, walk, reach, grasp, drive, ..."""
        return self._checked({"op": "behaviour", "name": name, **params})

    def try_behaviour(self, name: str, **params: Any) -> dict[str, Any]:
        """Start a behaviour and return the reply even if the run refused it."""
        return self.request({"op": "behaviour", "name": name, **params})

    def stop(self) -> dict[str, Any]:
        """End the run."""
        return self._checked({"op": "stop"})
