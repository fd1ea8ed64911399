"""What the simulator, field computer and CloudSim server roles get beyond the common plan."""

from __future__ import annotations

from constellations.plans.base import Action, PlanContext, PlanItem
from constellations.plans.software import (
    REMOTE_ROOT,
    install_source_bundle,
    install_wheelhouse,
    wait_for_port,
)
from provisioners.remote.operations import absent, directory, file, service, user
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
TEAM_USER = "team"  # the account team members log into on the field computers
TEAM_HOME = f"/home/{TEAM_USER}"
TEAM_SUDOERS = f"/etc/sudoers.d/cloudsim-{TEAM_USER}"
RUN_STATE_DIR = "/var/lib/cloudsim"  # current-run.json: readable by the team, written by us


def simulator(ctx: PlanContext) -> list[PlanItem]:
    """Install the bundled simulator (drcsim) into its own virtualenv."""
    return [install_wheelhouse(_wheelhouse(ctx), SIMULATOR_VENV, "drcsim")]


def field_computer(ctx: PlanContext) -> list[PlanItem]:
    """Install drcsim's client library (and example controller), which team code drives the
    robot with, without the physics engine (only sim needs it); make the team's account."""
    return [
        install_wheelhouse(_wheelhouse(ctx), SIMULATOR_VENV, "drcsim", only=CLIENT_ONLY),
        *team_account(ctx),
    ]


def team_account(ctx: PlanContext) -> list[PlanItem]:
    """The unprivileged `team` account: its members' keys exactly, sudo only if allowed.

    Its home is never touched again (code stays between runs). CloudSim's own keys live in
    /root (0700) and its run state is root's, except current-run.json, which is for them.
    """
    sudoers = f"# CloudSim: an officer let the team use sudo\n{TEAM_USER} ALL=(ALL) NOPASSWD:ALL\n"
    return [
        user(TEAM_USER),
        Action("team: keys only, no password", _no_password),
        directory(TEAM_HOME, mode=0o750, owner=TEAM_USER, group=TEAM_USER),
        directory(f"{TEAM_HOME}/.ssh", mode=0o700, owner=TEAM_USER, group=TEAM_USER),
        file(
            f"{TEAM_HOME}/.ssh/authorized_keys",
            "".join(f"{key}\n" for key in ctx.team_keys),
            mode=0o600,
            owner=TEAM_USER,
            group=TEAM_USER,
        ),
        file(TEAM_SUDOERS, sudoers, mode=0o440) if ctx.team_sudo else absent(TEAM_SUDOERS),
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


def _no_password(executor: SSHExecutor, target: SSHTarget) -> bool:
    """Give `team` no password rather than a locked one: sshd refuses a locked account's keys
    when it does not use PAM."""
    shadow = executor.run(target, f"getent shadow {TEAM_USER} | cut -d: -f2").stdout.strip()
    if shadow == "*":
        return False
    executor.run(target, f"usermod --password '*' {TEAM_USER}")
    return True


def _daemon_reload(executor: SSHExecutor, target: SSHTarget) -> bool:
    executor.run(target, "systemctl daemon-reload")
    return False


def _wheelhouse(ctx: PlanContext):  # type: ignore[no-untyped-def]
    if ctx.wheelhouse is None:
        raise ValueError(f"{ctx.machine.name}: this plan needs the simulator's wheelhouse")
    return ctx.wheelhouse
