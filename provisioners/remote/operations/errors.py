"""Errors of operations; part of the SSH layer's hierarchy."""

from __future__ import annotations

from typing import TYPE_CHECKING

from provisioners.remote.ssh import SSHError

if TYPE_CHECKING:
    from provisioners.remote.operations.base import OperationResult


class OperationError(SSHError):
    """Raise when an operation cannot reach its desired state."""


class TemplateError(OperationError):
    """Raise when a machine template is missing or fails to render; names file and line."""

    def __init__(self, template: str, line: int | None, message: str) -> None:
        self.template = template
        self.line = line
        self.message = message
        where = f"{template}, line {line}" if line is not None else template
        super().__init__(f"template {where}: {message}")


class DeployFailed(OperationError):
    """Raise when an operation of a deploy fails; carries the results before it."""

    def __init__(
        self,
        machine_name: str,
        operation_name: str,
        index: int,
        completed: list[OperationResult],
        cause: Exception,
    ) -> None:
        self.machine_name = machine_name
        self.operation_name = operation_name
        self.index = index
        self.completed = completed
        super().__init__(
            f"{machine_name}: operation {index + 1} ({operation_name}) failed: {cause}"
        )
