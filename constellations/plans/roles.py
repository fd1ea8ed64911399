"""What the simulator, field computer and CloudSim server roles get beyond the common plan."""

from __future__ import annotations

from constellations.plans.base import Action, PlanContext, PlanItem
from constellations.plans.members import member_accounts
from constellations.plans.software import (
    REMOTE_ROOT,
    install_source_bundle,
    install_wheelhouse,
    wait_for_port,
)
from provisioners.remote.operations import directory, file, service
from provisioners.remote.ssh import SSHExecutor, SSHTarget

SIMULATOR_VENV = "/opt/drcsim"
CLIENT_ONLY = ("drcsim", "pyzmq", "msgpack")
CLOUDSIM_ROOT = "/opt/cloudsim/src"
CLOUDSIM_VENV = "/opt/cloudsim/venv"
CLOUDSIM_ENV = "/etc/cloudsim/cloudsim.env"
CLOUDSIM_TLS_CERT = "/etc/cloudsim/tls.crt"
CLOUDSIM_TLS_KEY = "/etc/cloudsim/tls.key"
CLOUDSIM_INSTANCE = "/var/lib/cloudsim"
CLOUDSIM_PORT = 5000
CLOUDSIM_ADMIN_EMAIL = "admin@example.org"
RUN_STATE_DIR = "/var/lib/cloudsim"  # current-run.json: readable by the team, written by us


def simulator(ctx: PlanContext) -> list[PlanItem]:
    """Install the bundled simulator (drcsim) into its own virtualenv."""
    return [install_wheelhouse(_wheelhouse(ctx), SIMULATOR_VENV, "drcsim")]


def field_computer(ctx: PlanContext) -> list[PlanItem]:
    """Install drcsim's client library (and example controller), which team code drives the
    robot with, without the physics engine (only sim needs it); make the members' accounts.

    CloudSim's own keys live in /root (0700) and its run state is root's, except
    current-run.json, which is for the team.
    """
    return [
        install_wheelhouse(_wheelhouse(ctx), SIMULATOR_VENV, "drcsim", only=CLIENT_ONLY),
        *member_accounts(ctx),
        directory(RUN_STATE_DIR, mode=0o755),
    ]


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
            "admin_token": ctx.secrets["cloudsim_admin_token"],
            "tls_cert": CLOUDSIM_TLS_CERT,
            "tls_key": CLOUDSIM_TLS_KEY,
            "sim_min_rtf": ctx.sim_min_rtf,
            # the wheels it was installed with: its own launches build theirs from them
            "wheels": f"{REMOTE_ROOT}/{ctx.app_bundle.name}",
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
        # HTTPS only on the public side: the master's CA signed it and the master pins it
        file(CLOUDSIM_TLS_CERT, ctx.secrets["cloudsim_tls_cert"], mode=0o644),
        file(CLOUDSIM_TLS_KEY, ctx.secrets["cloudsim_tls_key"], mode=0o600),
        file("/etc/systemd/system/cloudsim.service", unit),
        Action("systemctl daemon-reload", _daemon_reload),
        service("cloudsim", running=True, enabled=True),
        wait_for_port(CLOUDSIM_PORT, 180),
    ]


def _daemon_reload(executor: SSHExecutor, target: SSHTarget) -> bool:
    executor.run(target, "systemctl daemon-reload")
    return False


def _wheelhouse(ctx: PlanContext):  # type: ignore[no-untyped-def]
    if ctx.wheelhouse is None:
        raise ValueError(f"{ctx.machine.name}: this plan needs the simulator's wheelhouse")
    return ctx.wheelhouse
