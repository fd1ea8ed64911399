"""Facts about iptables rules and chains."""

from __future__ import annotations

import re
import shlex
from dataclasses import dataclass

from provisioners.remote.facts.base import Fact

IPTABLES_TABLES = frozenset({"filter", "nat", "mangle", "raw", "security"})
CHAIN_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]{0,28}$")
# seconds to wait for the xtables lock another iptables call holds
XTABLES_WAIT_SECONDS = 10


def iptables_prefix(table: str, ipv6: bool) -> str:
    """Return "iptables -w N -t TABLE" (or ip6tables) with every word quoted."""
    check_table(table)
    binary = "ip6tables" if ipv6 else "iptables"
    return f"{binary} -w {XTABLES_WAIT_SECONDS} -t {shlex.quote(table)}"


def check_table(table: str) -> str:
    """Return the table name, refusing anything but iptables' own tables."""
    if table not in IPTABLES_TABLES:
        raise ValueError(f"not an iptables table: {table!r}")
    return table


def check_chain_name(chain: str) -> str:
    """Return the chain name, refusing anything iptables would not take as one."""
    if not CHAIN_NAME.match(chain):
        raise ValueError(f"not an iptables chain name: {chain!r}")
    return chain


@dataclass(frozen=True)
class _ChainFact:
    """A fact about one chain of one table, both names checked before anything runs."""

    table: str
    chain: str

    def __post_init__(self) -> None:
        check_table(self.table)
        check_chain_name(self.chain)


@dataclass(frozen=True)
class IptablesRuleFact(_ChainFact, Fact[bool]):
    """Whether a rule (its argv after the chain) is in a chain; asked with iptables -C."""

    rule: tuple[str, ...]
    ipv6: bool = False
    # -C exits 1 for "no such rule"
    ok_exit_codes = frozenset({0, 1})

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.rule:
            raise ValueError("empty iptables rule")

    @property
    def command(self) -> str:
        """Return iptables -C CHAIN RULE..."""
        prefix = iptables_prefix(self.table, self.ipv6)
        return f"{prefix} -C {shlex.quote(self.chain)} {shlex.join(self.rule)}"

    def parse(self, stdout: str, exit_code: int) -> bool:
        """Return whether -C found the rule."""
        return exit_code == 0


@dataclass(frozen=True)
class IptablesChainFact(_ChainFact, Fact[bool]):
    """Whether a chain exists in a table."""

    ipv6: bool = False

    @property
    def command(self) -> str:
        """Return a listing of the table's chain names, one per line."""
        prefix = iptables_prefix(self.table, self.ipv6)
        return f"{prefix} -S | sed -n 's/^-[NP] \\([^ ]*\\).*/\\1/p'"

    def parse(self, stdout: str, exit_code: int) -> bool:
        """Return whether the chain is among the listed names."""
        return self.chain in stdout.splitlines()


@dataclass(frozen=True)
class IptablesChainRulesFact(_ChainFact, Fact["tuple[bool, ...] | None"]):
    """Whether a chain holds exactly these rules: None without the chain, else for each rule
    whether it is in the chain, followed by False when the chain holds any other rule."""

    rules: tuple[tuple[str, ...], ...]
    ipv6: bool = False

    @property
    def command(self) -> str:
        """Return one line per rule (1 present, 0 not) and then the chain's rule count."""
        prefix = iptables_prefix(self.table, self.ipv6)
        chain = shlex.quote(self.chain)
        checks = "".join(
            f"{prefix} -C {chain} {shlex.join(rule)} 2>/dev/null && echo 1 || echo 0; "
            for rule in self.rules
        )
        return (
            f"if {prefix} -S {chain} >/dev/null 2>&1; then {checks}"
            f"{prefix} -S {chain} | grep -c '^-A' || true; fi"
        )

    def parse(self, stdout: str, exit_code: int) -> tuple[bool, ...] | None:
        """Return each rule's presence, then whether the chain holds nothing else."""
        lines = stdout.split()
        if not lines:
            return None
        present = tuple(line == "1" for line in lines[: len(self.rules)])
        return (*present, int(lines[-1]) == len(self.rules))
