"""Firewall rules and chains, kept idempotent by asking iptables first."""

from __future__ import annotations

import re
import shlex
from collections.abc import Iterator, Sequence

from provisioners.remote.facts import IptablesChainFact, IptablesRuleFact
from provisioners.remote.facts.iptables import (
    XTABLES_WAIT_SECONDS,
    IptablesChainRulesFact,
    iptables_prefix,
)
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


def iptables_chain_exact(
    chain: str, rules: Sequence[Sequence[str]], *, table: str = "filter", ipv6: bool = False
) -> Operation:
    """Ensure a user-defined chain holds exactly these rules, in this order.

    A rule left from an older plan (say, a wider accept) is removed, not kept beside the new
    ones. The chain is rewritten in one iptables-restore transaction, so it is never seen
    empty or half-filled.
    """
    wanted = tuple(tuple(rule) for rule in rules)
    fact = IptablesChainRulesFact(table, chain, wanted, ipv6)

    def plan(state: tuple[bool, ...] | None) -> Iterator[Step]:
        if state is not None and all(state):
            return
        restore = "\n".join(
            [
                f"*{table}",
                f":{chain} - [0:0]",  # with --noflush, declaring a user chain flushes it
                *(f"-A {chain} {_restore_words(rule)}" for rule in wanted),
                "COMMIT",
                "",
            ]
        )
        binary = "ip6tables-restore" if ipv6 else "iptables-restore"
        yield Command(
            f"printf %s {shlex.quote(restore)} | {binary} -w {XTABLES_WAIT_SECONDS} --noflush"
        )

    return Operation(f"iptables -t {table} {chain}: {len(wanted)} rules", (fact,), plan)


def _restore_words(rule: Sequence[str]) -> str:
    """Return a rule's words as iptables-restore reads them: double quotes only, where needed."""
    return " ".join(
        word if re.fullmatch(r"[\w@%+=:,./!-]+", word) else '"' + word.replace('"', '\\"') + '"'
        for word in rule
    )
