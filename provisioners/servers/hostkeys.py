"""Host keys of the inventory's servers: pinned in the inventory, else recorded in the state."""

from __future__ import annotations

from provisioners.servers.inventory import Inventory
from provisioners.servers.state import StateFile


class StateHostKeys:
    """A host key store (provisioners.ssh.HostKeyStore) trusting each server on first use."""

    def __init__(self, state: StateFile, inventory: Inventory) -> None:
        self._state = state
        self._inventory = inventory

    def get(self, machine_name: str) -> str | None:
        """Return the pinned or recorded host key of a server, None before first contact."""
        server = self._inventory.server(machine_name)
        if server is not None and server.host_key is not None:
            return server.host_key
        return self._state.read().host_keys.get(machine_name)

    def put(self, machine_name: str, key_type_and_base64: str) -> None:
        """Record a server's host key at first contact."""
        with self._state.transaction() as state:
            state.host_keys.setdefault(machine_name, key_type_and_base64)
