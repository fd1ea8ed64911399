"""Firewall rules and chains, kept idempotent by asking iptables first."""

from __future__ import annotations

import shlex
from collections.abc import Iterator, Sequence

from provisioners.remote.facts import IptablesChainFact, IptablesRuleFact
from provisioners.remote.facts.iptables import iptables_prefix
from provisioners.remote.operations.base import Command, Operation, Step


def iptables_rule(
    chain: str,
    rule: Sequence[str],
    *,
    table: str = "filter",
    insert: bool = False,
    ipv6: bool = False,
) -> Operation:
    """Ensure a rule (argv after the chain, e.g. ["-p", "udp", "-j", "ACCEPT"]) is in a chain."""
    fact = IptablesRuleFact(table, chain, tuple(rule), ipv6)
    action = "-I" if insert else "-A"

    def plan(present: bool) -> Iterator[Step]:
        if not present:
            prefix = iptables_prefix(table, ipv6)
            yield Command(f"{prefix} {action} {shlex.quote(chain)} {shlex.join(fact.rule)}")

    return Operation(f"iptables -t {table} {chain} {shlex.join(fact.rule)}", (fact,), plan)


def iptables_chain(chain: str, *, table: str = "filter", ipv6: bool = False) -> Operation:
    """Ensure a user-defined chain exists in a table."""
    fact = IptablesChainFact(table, chain, ipv6)

    def plan(exists: bool) -> Iterator[Step]:
        if not exists:
            yield Command(f"{iptables_prefix(table, ipv6)} -N {shlex.quote(chain)}")

    return Operation(f"iptables chain -t {table} {chain}", (fact,), plan)
