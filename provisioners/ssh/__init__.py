"""Reach machines over SSH: run commands, move files, many machines at once."""

from provisioners.ssh.connections import ConnectPolicy
from provisioners.ssh.errors import (
    CommandFailed,
    CommandTimeout,
    ConnectError,
    GroupError,
    HostKeyMismatch,
    SSHError,
)
from provisioners.ssh.executor import SSHExecutor
from provisioners.ssh.hostkeys import HostKeyStore, InMemoryHostKeyStore, fingerprint
from provisioners.ssh.machine import Machine, load_private_key
from provisioners.ssh.output import LogSink, SecretMasker
from provisioners.ssh.result import CommandResult, Transfer

__all__ = [
    "CommandFailed",
    "CommandResult",
    "CommandTimeout",
    "ConnectError",
    "ConnectPolicy",
    "GroupError",
    "HostKeyMismatch",
    "HostKeyStore",
    "InMemoryHostKeyStore",
    "LogSink",
    "Machine",
    "SSHError",
    "SSHExecutor",
    "SecretMasker",
    "Transfer",
    "fingerprint",
    "load_private_key",
]
