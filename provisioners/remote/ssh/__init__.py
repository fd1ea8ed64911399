"""Reach machines over SSH: run commands, move files, many machines at once."""

from provisioners.remote.ssh.cache import CacheStats, ConnectionCache, process_cache
from provisioners.remote.ssh.connections import ConnectPolicy
from provisioners.remote.ssh.errors import (
    CommandFailed,
    CommandTimeout,
    ConnectError,
    ConnectionLost,
    GroupError,
    HostKeyMismatch,
    Interrupted,
    SSHError,
)
from provisioners.remote.ssh.executor import SSHExecutor
from provisioners.remote.ssh.hostkeys import HostKeys, HostKeyStore, fingerprint
from provisioners.remote.ssh.output import LogSink, SecretMasker
from provisioners.remote.ssh.result import CommandResult, Transfer
from provisioners.remote.ssh.target import Route, SSHTarget, load_private_key

__all__ = [
    "CacheStats",
    "CommandFailed",
    "CommandResult",
    "CommandTimeout",
    "ConnectError",
    "ConnectPolicy",
    "ConnectionCache",
    "ConnectionLost",
    "GroupError",
    "HostKeyMismatch",
    "HostKeyStore",
    "HostKeys",
    "Interrupted",
    "LogSink",
    "Route",
    "SSHError",
    "SSHExecutor",
    "SSHTarget",
    "SecretMasker",
    "Transfer",
    "fingerprint",
    "load_private_key",
    "process_cache",
]
