"""Idempotent provisioning operations: read facts, change only what differs."""

from provisioners.operations.base import (
    Command,
    Operation,
    OperationResult,
    Step,
    Upload,
    apply,
    plan_on,
)
from provisioners.operations.deploy import Deploy
from provisioners.operations.errors import DeployFailed, OperationError, TemplateError
from provisioners.operations.files import directory, file, template
from provisioners.operations.iptables import iptables_chain, iptables_rule
from provisioners.operations.packages import deb_packages
from provisioners.operations.routes import default_route
from provisioners.operations.services import service
from provisioners.operations.sysctl import sysctl
from provisioners.operations.templates import MachineTemplates
from provisioners.operations.users import authorized_key, user

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
    "apply",
    "authorized_key",
    "deb_packages",
    "default_route",
    "directory",
    "file",
    "iptables_chain",
    "iptables_rule",
    "plan_on",
    "service",
    "sysctl",
    "template",
    "user",
]
