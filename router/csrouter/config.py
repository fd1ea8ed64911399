"""The daemon's configuration: a JSON file the router plan writes (defaults for the rest)."""

from __future__ import annotations

import ipaddress
import json
import re
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from csrouter.errors import ConfigError

DEFAULT_CONFIG_PATH = "/etc/cloudsim/router.json"
DEFAULT_SOCKET = "/run/csrouter/control.sock"
DEFAULT_BANDWIDTH_LOG = "/var/log/cloudsim/bandwidth.log"
DEFAULT_STATE_FILE = "/var/lib/cloudsim/router/state.json"
DEFAULT_LATENCY_MS = 250
UPLINK_QUEUE, DOWNLINK_QUEUE = 0, 1  # the NFQUEUE numbers CloudSim's router plan uses
MAX_LATENCY_MS = 2000
_DEVICE = re.compile(r"^[A-Za-z0-9_.-]{1,15}$")


@dataclass(frozen=True)
class RouterConfig:
    """Where the OCU path is (LAN subnet, VPN device, queues) and where files go."""

    lan_subnet: str
    vpn_network: str = "10.8.0.0/24"
    vpn_device: str = "tun-ocu"
    uplink_queue: int = UPLINK_QUEUE
    downlink_queue: int = DOWNLINK_QUEUE
    socket: str = DEFAULT_SOCKET
    bandwidth_log: str = DEFAULT_BANDWIDTH_LOG
    state_file: str = DEFAULT_STATE_FILE
    default_latency_ms: int = DEFAULT_LATENCY_MS
    queue_max_packets: int = 65536

    def __post_init__(self) -> None:
        for name in ("lan_subnet", "vpn_network"):
            try:
                ipaddress.ip_network(getattr(self, name))
            except ValueError as exc:
                raise ConfigError(f"{name} {getattr(self, name)!r} is not a network") from exc
        if not _DEVICE.match(self.vpn_device):
            raise ConfigError(f"vpn_device {self.vpn_device!r} is not an interface name")
        queues = (self.uplink_queue, self.downlink_queue)
        if len(set(queues)) != 2 or not all(0 <= q <= 65535 for q in queues):
            raise ConfigError(f"queues must be two distinct numbers 0-65535, not {queues}")
        check_latency(self.default_latency_ms)
        if self.queue_max_packets < 1:
            raise ConfigError("queue_max_packets must be positive")

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RouterConfig:
        """Build a configuration from parsed JSON, refusing unknown keys."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ConfigError(f"unknown configuration keys: {', '.join(unknown)}")
        if "lan_subnet" not in data:
            raise ConfigError("the configuration needs lan_subnet")
        return cls(**data)


def load_config(path: str | Path = DEFAULT_CONFIG_PATH) -> RouterConfig:
    """Read the configuration file."""
    try:
        data = json.loads(Path(path).read_text())
    except OSError as exc:
        raise ConfigError(f"cannot read {path}: {exc.strerror}") from exc
    except json.JSONDecodeError as exc:
        raise ConfigError(f"{path} is not JSON: {exc}") from exc
    if not isinstance(data, dict):
        raise ConfigError(f"{path} must hold a JSON object")
    return RouterConfig.from_dict(data)


def check_latency(latency_ms: int) -> int:
    """Return the latency if it is a whole number of ms in 0..MAX_LATENCY_MS."""
    if isinstance(latency_ms, bool) or not isinstance(latency_ms, int):
        raise ConfigError(f"latency must be whole milliseconds, not {latency_ms!r}")
    if not 0 <= latency_ms <= MAX_LATENCY_MS:
        raise ConfigError(f"latency must be 0-{MAX_LATENCY_MS} ms, not {latency_ms}")
    return latency_ms


def check_cap(name: str, bits: int | None) -> int | None:
    """Return a cap in bits (None = no cap) if it is a non-negative whole number."""
    if bits is None:
        return None
    if isinstance(bits, bool) or not isinstance(bits, int) or bits < 0:
        raise ConfigError(f"{name} must be a non-negative number of bits, not {bits!r}")
    return bits
