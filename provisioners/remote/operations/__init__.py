"""Idempotent provisioning operations: read facts, change only what differs."""

from provisioners.remote.operations.base import (
    Command,
    Operation,
    OperationResult,
    Step,
    Upload,
    apply,
    plan_on,
)
from provisioners.remote.operations.deploy import Deploy
from provisioners.remote.operations.errors import DeployFailed, OperationError, TemplateError
from provisioners.remote.operations.files import absent, directory, file, template
from provisioners.remote.operations.iptables import (
    iptables_chain,
    iptables_chain_exact,
    iptables_rule,
)
from provisioners.remote.operations.packages import deb_packages
from provisioners.remote.operations.routes import default_route
from provisioners.remote.operations.services import service
from provisioners.remote.operations.sysctl import sysctl
from provisioners.remote.operations.templates import MachineTemplates
from provisioners.remote.operations.users import authorized_key, user

__all__ = [
    "Command",
    "Deploy",
    "DeployFailed",
    "MachineTemplates",
    "Operation",
    "OperationError",
    "OperationResult",
    "Step",
    "TemplateError",
    "Upload",
    "absent",
    "apply",
    "authorized_key",
    "deb_packages",
    "default_route",
    "directory",
    "file",
    "iptables_chain",
    "iptables_chain_exact",
    "iptables_rule",
    "plan_on",
    "service",
    "sysctl",
    "template",
    "user",
]
