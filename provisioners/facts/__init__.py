"""Facts: small read-only probes of a machine's state, parsed into values."""

from provisioners.facts.base import Fact, FactError, read_fact
from provisioners.facts.files import PathFact, PathState
from provisioners.facts.iptables import IptablesChainFact, IptablesRuleFact
from provisioners.facts.packages import DebPackagesFact
from provisioners.facts.services import ServiceFact, ServiceState
from provisioners.facts.sysctl import SysctlFact
from provisioners.facts.users import AuthorizedKeysFact, AuthorizedKeysState, UserFact, UserState

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
