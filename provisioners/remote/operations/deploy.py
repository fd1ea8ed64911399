"""Apply a list of operations to a machine in order, stopping at the first failure."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from provisioners.remote.operations.base import Operation, OperationResult, apply
from provisioners.remote.operations.errors import DeployFailed
from provisioners.remote.ssh import SSHError, SSHExecutor, SSHTarget


@dataclass(frozen=True)
class Deploy:
    """An ordered list of operations, e.g. one role's plan."""

    operations: Sequence[Operation]

    def apply(
        self, executor: SSHExecutor, machine: SSHTarget, *, sudo: bool = False
    ) -> list[OperationResult]:
        """Apply every operation in order; raise DeployFailed naming the one that failed."""
        results: list[OperationResult] = []
        for index, operation in enumerate(self.operations):
            try:
                results.append(apply(executor, machine, operation, sudo=sudo))
            except SSHError as exc:
                executor.log(machine.name, f"[{operation.name}] failed: {exc}")
                raise DeployFailed(machine.name, operation.name, index, results, exc) from exc
        return results
