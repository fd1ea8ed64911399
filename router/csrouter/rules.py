"""The iptables rules that send OCU<->LAN packets to the daemon's queues.

They have no --queue-bypass on purpose: while no process listens on a queue the kernel
drops its packets, so OCU traffic stops instead of flowing undelayed and uncounted. The
daemon adds missing rules when it starts and never removes them.
"""

from __future__ import annotations

import shlex
import subprocess

from csrouter.config import RouterConfig
from csrouter.errors import RulesError

TABLE = "mangle"
CHAIN = "CLOUDSIM-OCU"
XTABLES_WAIT_SECONDS = 10


def queue_rules(config: RouterConfig) -> list[tuple[str, list[str]]]:
    """Return (chain, rule argv) for every rule, the chain's own rules first."""
    device, lan = config.vpn_device, config.lan_subnet
    uplink = ["-j", "NFQUEUE", "--queue-num", str(config.uplink_queue)]
    downlink = ["-j", "NFQUEUE", "--queue-num", str(config.downlink_queue)]
    return [
        (CHAIN, ["-i", device, "-d", lan, *uplink]),
        (CHAIN, ["-s", lan, "-o", device, *downlink]),
        ("FORWARD", ["-j", CHAIN]),
    ]


def _iptables(*args: str) -> subprocess.CompletedProcess[str]:
    command = ["iptables", "-w", str(XTABLES_WAIT_SECONDS), "-t", TABLE, *args]
    try:
        return subprocess.run(command, capture_output=True, text=True, check=False, timeout=30)
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise RulesError(f"{shlex.join(command)} failed: {exc}") from exc


def _chain_exists() -> bool:
    return _iptables("-S", CHAIN).returncode == 0


def missing_rules(config: RouterConfig) -> list[str]:
    """Return the rules that are not in place, as iptables arguments (empty = all there)."""
    if not _chain_exists():
        return [f"-N {CHAIN}"] + [f"-A {c} {shlex.join(r)}" for c, r in queue_rules(config)]
    return [
        f"-A {chain} {shlex.join(rule)}"
        for chain, rule in queue_rules(config)
        if _iptables("-C", chain, *rule).returncode != 0
    ]


def ensure_rules(config: RouterConfig) -> list[str]:
    """Add whatever rule is missing; return what was added."""
    added: list[str] = []
    if not _chain_exists():
        _checked(_iptables("-N", CHAIN))
        added.append(f"-N {CHAIN}")
    for chain, rule in queue_rules(config):
        if _iptables("-C", chain, *rule).returncode == 0:
            continue
        # the jump goes first so no earlier mangle rule can let OCU packets skip the queues
        where = ["-I", chain, "1"] if chain == "FORWARD" else ["-A", chain]
        _checked(_iptables(*where, *rule))
        added.append(f"{where[0]} {chain} {shlex.join(rule)}")
    return added


def _checked(result: subprocess.CompletedProcess[str]) -> None:
    if result.returncode != 0:
        raise RulesError(f"iptables {shlex.join(result.args[1:])}: {result.stderr.strip()}")
