"""Facts: small read-only probes of a machine's state, parsed into values."""

from provisioners.remote.facts.base import Fact, FactError, read_fact
from provisioners.remote.facts.files import PathFact, PathState
from provisioners.remote.facts.iptables import IptablesChainFact, IptablesRuleFact
from provisioners.remote.facts.packages import DebPackagesFact
from provisioners.remote.facts.services import ServiceFact, ServiceState
from provisioners.remote.facts.sysctl import SysctlFact
from provisioners.remote.facts.users import (
    AuthorizedKeysFact,
    AuthorizedKeysState,
    UserFact,
    UserState,
)

__all__ = [
    "AuthorizedKeysFact",
    "AuthorizedKeysState",
    "DebPackagesFact",
    "Fact",
    "FactError",
    "IptablesChainFact",
    "IptablesRuleFact",
    "PathFact",
    "PathState",
    "ServiceFact",
    "ServiceState",
    "SysctlFact",
    "UserFact",
    "UserState",
    "read_fact",
]
