"""What deploy plans need that the launch job makes for them: wheelhouses, bundles, VPN keys.

Plans declare their needs (constellations.plans.NEEDS); each need has a supplier here that
returns the PlanContext fields it fills. No plan is named: a new plan with known needs
changes nothing here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from cloudsim.config import Config
from cloudsim.jobs.heartbeat import reporting_wait
from cloudsim.jobs.runner import JobContext
from cloudsim.launched_constellations.keys import (
    instance_admin_password,
    instance_admin_token,
    instance_tls,
)
from cloudsim.launched_constellations.vpn import server_material
from cloudsim.models import Constellation
from constellations.definition import ConstellationKind
from constellations.plans import Need, PlanContext, needs_of
from constellations.plans.roles import SIMULATOR_VENV
from constellations.plans.router import CSROUTER_VENV
from constellations.plans.software import (
    build_source_bundle,
    build_wheelhouse,
    distribution_source,
    preinstall_command,
)
from provisioners.providers.base import CloudSimNodeDriver
from provisioners.providers.errors import ProviderError
from provisioners.remote.ssh import SSHExecutor

# What a provider with image layers (local) installs once for all machines instead of on each:
# the distribution, the virtualenv the plans install it into, the requirement.
PREINSTALLED = {
    Need.SIMULATOR_WHEELS: ("drcsim", SIMULATOR_VENV, "drcsim"),
    Need.ROUTER_WHEELS: ("cloudsim-router", CSROUTER_VENV, "cloudsim-router"),
}


@dataclass(frozen=True)
class Supply:
    """What a supplier may use: the job (log, masks), the executor (masks), the app's settings."""

    ctx: JobContext
    executor: SSHExecutor
    constellation: Constellation
    config: Config

    def secret(self, value: str) -> str:
        """Keep value out of the job log and the SSH log; return it."""
        self.ctx.mask(value)
        self.executor.add_secret(value)
        return value

    def wheels(self, distribution: str) -> Path:
        """Return a wheelhouse of an installed distribution and its dependencies (cached)."""
        cache = self.config.instance_dir / "wheelhouse"
        return build_wheelhouse(
            distribution_source(distribution), cache, self.config.machine_python
        )


def _simulator_wheels(supply: Supply) -> dict[str, Any]:
    supply.ctx.log("building the simulator's wheelhouse (cached after the first time)")
    return {"wheelhouse": supply.wheels("drcsim")}


def _router_wheels(supply: Supply) -> dict[str, Any]:
    supply.ctx.log("building the router's wheelhouse (cached after the first time)")
    return {"router_wheelhouse": supply.wheels("cloudsim-router")}


def _vpn(supply: Supply) -> dict[str, Any]:
    supply.ctx.log("making the team VPN's keys")
    material = server_material(supply.constellation)
    supply.secret(material.server_key)
    return {"vpn": material}


def _cloudsim_bundle(supply: Supply) -> dict[str, Any]:
    supply.ctx.log("bundling CloudSim's source and wheels (cached after the first time)")
    password = supply.secret(instance_admin_password(supply.constellation))
    token = supply.secret(instance_admin_token(supply.constellation))
    tls = instance_tls(supply.constellation)
    supply.secret(tls.key)
    # stored now: an uncommitted write would hold SQLite's lock through the whole install,
    # and every other job's log lines would wait for it
    supply.ctx.checkpoint()
    # the machines' packages CloudSim imports come from the same checkout, installed alike
    members = [distribution_source("drcsim"), distribution_source("cloudsim-router")]
    bundle = build_source_bundle(
        distribution_source("cloudsim"),
        supply.config.instance_dir / "wheelhouse",
        supply.config.machine_python,
        members,
    )
    secrets = {
        "cloudsim_admin_password": password,
        "cloudsim_admin_token": token,
        "cloudsim_tls_cert": tls.cert,
        "cloudsim_tls_key": tls.key,
    }
    return {"app_bundle": bundle, "secrets": secrets}


SUPPLIERS: dict[Need, Callable[[Supply], dict[str, Any]]] = {
    Need.SIMULATOR_WHEELS: _simulator_wheels,
    Need.ROUTER_WHEELS: _router_wheels,
    Need.VPN: _vpn,
    Need.CLOUDSIM_BUNDLE: _cloudsim_bundle,
}


def supply_needs(supply: Supply, contexts: dict[str, PlanContext]) -> dict[str, PlanContext]:
    """Return the plan contexts with what each machine's plans need filled in."""
    wanted = {name: needs_of(c.machine.plan) for name, c in contexts.items()}
    everything = frozenset().union(*wanted.values())
    for need in (need for need in Need if need in everything):
        fields = SUPPLIERS[need](supply)
        contexts = {
            name: replace(c, **fields) if need in wanted[name] else c
            for name, c in contexts.items()
        }
    return contexts


def preinstall(
    log: Callable[[str], None], driver: CloudSimNodeDriver, kind: ConstellationKind, config: Config
) -> None:
    """Install the kind's wheelhouses once into the provider's image, where it has layers:
    the machines' plans then find them installed instead of each uploading and installing."""
    wanted = frozenset().union(*(needs_of(m.plan) for m in kind.machines))
    for need, (distribution, venv, requirement) in PREINSTALLED.items():
        if need not in wanted:
            continue
        try:
            # the first launch builds both (minutes on a loaded machine); each has a deadline
            with reporting_wait(log, f"installing {requirement} into the machines' image"):
                wheels = build_wheelhouse(
                    distribution_source(distribution),
                    config.instance_dir / "wheelhouse",
                    config.machine_python,
                )
                command = preinstall_command(wheels, venv, requirement)
                made = driver.ex_image_layer(wheels.name, command)
        except ProviderError as exc:
            log(f"could not install {requirement} into the image ({exc}): each machine will")
            continue
        if made is None:
            return  # the provider has no image layers: the plans install on each machine
        if made:
            log(f"installed {requirement} into {venv} in the machines' image ({wheels.name})")
