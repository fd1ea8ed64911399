"""Give a master back its account and token on a team instance, through the instance's SSH
route (`cloudsim instance restore-access NAME`, run on the master).

The instance refuses to disable, demote or delete the master's account and to revoke its
token; they can still be lost (a database restored from an old backup, someone with root on
the machine). The master deployed the machine and keeps its SSH key: it runs the instance's
own `cloudsim instance restore-access --here` there, which puts back the account and token the
instance's settings file names (the ones the master installed), then checks that its calls
are answered again.
"""

from __future__ import annotations

import shlex

from cloudsim.config import Config
from cloudsim.errors import CloudSimError, Conflict
from cloudsim.launched_constellations.connect import machine_host_keys, targets
from cloudsim.launched_constellations.keys import constellation_keypair
from cloudsim.models import ConstellationState, TeamInstance
from constellations.plans.roles import CLOUDSIM_ENV, CLOUDSIM_VENV
from provisioners.remote.ssh import ConnectPolicy, SSHError, SSHExecutor

RESTORE_TIMEOUT = 120


class RestoreError(CloudSimError):
    """The instance's machine could not be reached, or the command there failed."""

    status = 502


def with_settings(argv: list[str]) -> str:
    """Return a shell command running one of the instance's programs with its settings."""
    program = shlex.join([f"{CLOUDSIM_VENV}/bin/{argv[0]}", *argv[1:]])
    return f"set -a && . {shlex.quote(CLOUDSIM_ENV)} && set +a && {program}"


def restore_command() -> str:
    """Return the shell command that restores the master's access on the instance's machine."""
    return with_settings(["cloudsim", "instance", "restore-access", "--here"])


def run_on_instance(instance: TeamInstance, config: Config, command: str) -> str:
    """Run a shell command as root on the instance's machine (its SSH route); return stdout."""
    constellation = instance.constellation
    if constellation.state != ConstellationState.READY:
        raise Conflict(f"{instance.name}'s machine is {constellation.state.value}, not ready")
    server = next((m for m in constellation.machines if m.role == "cloudsim"), None)
    if server is None:
        raise Conflict(f"{instance.name} has no CloudSim machine")
    keys = constellation_keypair(constellation)
    target = targets(constellation, keys, config)[server.name]
    executor = SSHExecutor(
        machine_host_keys(constellation),
        secrets=[keys.private],
        connect_policy=ConnectPolicy(deadline=60),
    )
    try:
        with executor:
            sudo = target.user != "root"
            return executor.run(target, command, timeout=RESTORE_TIMEOUT, sudo=sudo).stdout
    except SSHError as exc:
        raise RestoreError(f"{instance.name}: {exc}") from None


def restore_access(instance: TeamInstance, config: Config) -> list[str]:
    """Run the restore on the instance's machine over SSH; return what it put back."""
    output = run_on_instance(instance, config, restore_command())
    return [line for line in output.splitlines() if line.strip()]
