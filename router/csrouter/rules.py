"""The iptables rules that send OCU<->LAN packets to the daemon's queues.

They have no --queue-bypass on purpose: while no process listens on a queue the kernel
drops its packets, so OCU traffic stops instead of flowing undelayed and uncounted. The
daemon adds missing rules when it starts and never removes them.

A packet held after connection tracking saw it leaves its flow's conntrack entry
unconfirmed; a second packet of the same flow arriving meanwhile (a ping every 200 ms with
250 ms each way) creates a clashing entry and is dropped when released. So every packet
that may start a flow is queued in raw/PREROUTING, before conntrack: the OCU's packets to
the LAN (uplink), and LAN packets addressed to a VPN client (downlink of flows the LAN
starts). Replies to the OCU's own flows reach the router addressed to its LAN address
(the OCU is masqueraded); they are queued in mangle/FORWARD once the router has undone the
masquerading (`--ctstate SNAT`), and their flow is long confirmed by then.
"""

from __future__ import annotations

import shlex
import subprocess
from dataclasses import dataclass

from csrouter.config import RouterConfig
from csrouter.errors import RulesError

CHAIN = "CLOUDSIM-OCU"
XTABLES_WAIT_SECONDS = 10


@dataclass(frozen=True)
class Rule:
    """One iptables rule: table, chain and the arguments after the chain."""

    table: str
    chain: str
    args: tuple[str, ...]

    def describe(self) -> str:
        """Return the rule as `-t TABLE -A CHAIN ARGS`."""
        return f"-t {self.table} -A {self.chain} {shlex.join(self.args)}"


def queue_rules(config: RouterConfig) -> list[Rule]:
    """Return every rule, each table's own chain before the jump into it."""
    device, lan, vpn = config.vpn_device, config.lan_subnet, config.vpn_network
    uplink = ("-j", "NFQUEUE", "--queue-num", str(config.uplink_queue))
    downlink = ("-j", "NFQUEUE", "--queue-num", str(config.downlink_queue))
    return [
        # not the router's own LAN address: the firewall drops what clients send it
        Rule("raw", CHAIN, ("-i", device, "-d", lan, "-m", "addrtype", "!", "--dst-type",
                            "LOCAL", *uplink)),
        Rule("raw", CHAIN, ("-s", lan, "-d", vpn, *downlink)),
        Rule("raw", "PREROUTING", ("-j", CHAIN)),
        Rule("mangle", CHAIN, ("-s", lan, "-o", device, "-m", "conntrack", "--ctstate", "SNAT",
                               *downlink)),
        Rule("mangle", "FORWARD", ("-j", CHAIN)),
    ]  # fmt: skip


def _iptables(table: str, *args: str) -> subprocess.CompletedProcess[str]:
    command = ["iptables", "-w", str(XTABLES_WAIT_SECONDS), "-t", table, *args]
    try:
        return subprocess.run(command, capture_output=True, text=True, check=False, timeout=30)
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise RulesError(f"{shlex.join(command)} failed: {exc}") from exc


def _present(rule: Rule) -> bool:
    return _iptables(rule.table, "-C", rule.chain, *rule.args).returncode == 0


def missing_rules(config: RouterConfig) -> list[str]:
    """Return the rules that are not in place (empty = all there)."""
    return [rule.describe() for rule in queue_rules(config) if not _present(rule)]


def ensure_rules(config: RouterConfig) -> list[str]:
    """Add whatever rule (or chain) is missing; return what was added."""
    added: list[str] = []
    for table in sorted({rule.table for rule in queue_rules(config)}):
        if _iptables(table, "-S", CHAIN).returncode != 0:
            _checked(_iptables(table, "-N", CHAIN))
            added.append(f"-t {table} -N {CHAIN}")
    for rule in queue_rules(config):
        if _present(rule):
            continue
        # jumps go first so no earlier rule lets OCU packets skip the queues
        where = ["-A", rule.chain] if rule.chain == CHAIN else ["-I", rule.chain, "1"]
        _checked(_iptables(rule.table, *where, *rule.args))
        added.append(rule.describe())
    return added


def _checked(result: subprocess.CompletedProcess[str]) -> None:
    if result.returncode != 0:
        raise RulesError(f"{shlex.join(result.args)}: {result.stderr.strip()}")
