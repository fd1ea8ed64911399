"""What the simulator, field computer and CloudSim server roles get beyond the common plan."""

from __future__ import annotations

from constellations.plans.base import Action, PlanContext, PlanItem
from constellations.plans.software import (
    install_source_bundle,
    install_wheelhouse,
    wait_for_port,
)
from provisioners.remote.operations import directory, file, service
from provisioners.remote.ssh import Machine as Target
from provisioners.remote.ssh import SSHExecutor

SIMULATOR_VENV = "/opt/drcsim"
CLIENT_ONLY = ("drcsim", "pyzmq", "msgpack")
CLOUDSIM_ROOT = "/opt/cloudsim/src"
CLOUDSIM_VENV = "/opt/cloudsim/venv"
CLOUDSIM_ENV = "/etc/cloudsim/cloudsim.env"
CLOUDSIM_INSTANCE = "/var/lib/cloudsim"
CLOUDSIM_PORT = 5000
CLOUDSIM_ADMIN_EMAIL = "admin@example.org"


def simulator(ctx: PlanContext) -> list[PlanItem]:
    """Install the bundled simulator (drcsim) into its own virtualenv."""
    return [install_wheelhouse(_wheelhouse(ctx), SIMULATOR_VENV, "drcsim")]


def field_computer(ctx: PlanContext) -> list[PlanItem]:
    """Install drcsim's client library (and example controller), which team code drives the
    robot with: without the physics engine, which only sim needs."""
    return [install_wheelhouse(_wheelhouse(ctx), SIMULATOR_VENV, "drcsim", only=CLIENT_ONLY)]


def cloudsim_server(ctx: PlanContext) -> list[PlanItem]:
    """Install CloudSim itself from its source bundle and run it (`cloudsim up`) under systemd."""
    if ctx.app_bundle is None:
        raise ValueError(f"{ctx.machine.name}: this plan needs CloudSim's source bundle")
    env = ctx.templates.render(
        "cloudsim/env.j2",
        {
            "instance_dir": CLOUDSIM_INSTANCE,
            "port": CLOUDSIM_PORT,
            "admin_email": CLOUDSIM_ADMIN_EMAIL,
            "admin_password": ctx.secrets["cloudsim_admin_password"],
        },
    )
    unit = ctx.templates.render(
        "cloudsim/cloudsim.service.j2",
        {
            "constellation": ctx.constellation,
            "env_file": CLOUDSIM_ENV,
            "root": CLOUDSIM_ROOT,
            "venv": CLOUDSIM_VENV,
        },
    )
    return [
        install_source_bundle(ctx.app_bundle, CLOUDSIM_ROOT, CLOUDSIM_VENV),
        directory("/etc/cloudsim", mode=0o700),
        file(CLOUDSIM_ENV, env, mode=0o600),
        file("/etc/systemd/system/cloudsim.service", unit),
        Action("systemctl daemon-reload", _daemon_reload),
        service("cloudsim", running=True, enabled=True),
        wait_for_port(CLOUDSIM_PORT, 180),
    ]


def _daemon_reload(executor: SSHExecutor, target: Target) -> bool:
    executor.run(target, "systemctl daemon-reload")
    return False


def _wheelhouse(ctx: PlanContext):  # type: ignore[no-untyped-def]
    if ctx.wheelhouse is None:
        raise ValueError(f"{ctx.machine.name}: this plan needs the simulator's wheelhouse")
    return ctx.wheelhouse
