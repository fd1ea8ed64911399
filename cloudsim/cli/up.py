"""`cloudsim up`: migrate, make the first admin, then run Redis, the workers and the web server."""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

import click
from sqlalchemy import select

from cloudsim import migrate
from cloudsim.auth.master import note_started, restore_master_access
from cloudsim.auth.policy import SYSTEM
from cloudsim.cli import app_context, reports_errors
from cloudsim.competition.demo import schedule_demo
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.launched_constellations.service import launch
from cloudsim.models import Constellation, ConstellationState, Team
from cloudsim.people.service import create_team, ensure_first_admin
from cloudsim.runtime.celery_argv import beat_argv, worker_argv
from cloudsim.runtime.redis_server import redis_command
from cloudsim.runtime.supervisor import Service, Supervisor, port_open

# sun_path holds 108 bytes with its final NUL
MAX_SOCKET_PATH = 107


def _host_port(bind: str) -> tuple[str, int]:
    host, _, port = bind.rpartition(":")
    if not host or not port.isdigit():
        raise click.ClickException(f"CLOUDSIM_BIND must look like HOST:PORT, got {bind!r}")
    return host, int(port)


def _services(config: Config) -> list[tuple[Service, float]]:
    """Return the services to run, in start order, with how long each may take to be ready."""
    env = dict(os.environ)
    env["CLOUDSIM_INSTANCE_DIR"] = str(config.instance_dir)
    env["CLOUDSIM_REDIS_URL"] = config.effective_redis_url
    json_logs = config.log_format == "json"
    python = sys.executable
    services: list[tuple[Service, float]] = []
    if config.redis_url is None:
        if port_open("127.0.0.1", config.redis_port)():
            raise click.ClickException(
                f"port {config.redis_port} is taken; set CLOUDSIM_REDIS_PORT or CLOUDSIM_REDIS_URL"
            )
        argv = redis_command(config.redis_port, config.instance_dir / "redis")
        services.append(
            (Service("redis", argv, env, port_open("127.0.0.1", config.redis_port)), 15)
        )
    services.append((Service("worker", worker_argv(config), env), 0))
    services.append((Service("beat", beat_argv(config), env), 0))
    host, port = _host_port(config.bind)
    tls = ["--certfile", config.tls_cert, "--keyfile", config.tls_key] if config.tls_cert else []
    # JSON: gunicorn's own lines as JSON, and the app logs each request (with its ids) itself
    logs = (
        ["--logger-class", "cloudsim.monitoring.logs.JsonGunicornLogger"]
        if json_logs
        else ["--access-logfile", "-"]
    )
    services.append(
        (
            Service(
                "web",
                [
                    python,
                    "-m",
                    "gunicorn",
                    "--bind",
                    config.bind,
                    # Threads, not one process per connection: a client's connection stays
                    # open between its requests (keep-alive) instead of a new TCP connection
                    # and accept per request; CPU work is still spread over the processes.
                    # gthread, whose own error answers (414, 400) carry security headers
                    "--worker-class",
                    "cloudsim.web.gunicorn_worker.SecureThreadWorker",
                    *_control_socket(config.instance_dir),
                    "--workers",
                    str(config.web_workers),
                    "--threads",
                    str(config.web_threads),
                    *logs,
                    "--log-level",
                    config.log_level.lower(),
                    *tls,
                    "cloudsim.wsgi:app",
                ],
                {**env, "PROMETHEUS_MULTIPROC_DIR": str(_metrics_dir(config))},
                port_open(host, port),
            ),
            60,
        )
    )
    return services


def _control_socket(instance_dir: Path) -> list[str]:
    """Return gunicorn's control socket option: in the instance folder, so that two CloudSims
    on one machine never share (and delete) one; none where the path is too long for a socket."""
    path = instance_dir / "gunicorn.ctl"
    if len(os.fsencode(path)) > MAX_SOCKET_PATH:
        return ["--no-control-socket"]
    return ["--control-socket", str(path)]


def _metrics_dir(config: Config) -> Path:
    """Return an empty folder for the web processes' request timings (prometheus_client's
    multiprocess mode: gunicorn's workers each write theirs, /metrics sums them)."""
    folder = config.instance_dir / "metrics"
    shutil.rmtree(folder, ignore_errors=True)  # counts of processes gone with a previous run
    folder.mkdir(mode=0o700)
    return folder


DEMO_TEAM = "Demo team"
DEMO_CONSTELLATION = "demo"


def _launch_demo(base_url: str) -> None:
    """Launch a local vrc constellation and a task the example controller runs, for a demo team."""
    if os.geteuid() != 0:
        click.echo("demo skipped: the local provider needs root", err=True)
        return
    with app_context():
        existing = db.session.scalar(
            select(Constellation).where(
                Constellation.name == DEMO_CONSTELLATION,
                Constellation.state != ConstellationState.TERMINATED,
            )
        )
        if existing is not None:
            click.echo(
                f"demo constellation: {base_url}constellations/{existing.id} "
                f"({existing.state.value})"
            )
            return
        team = db.session.scalar(select(Team).where(Team.name == DEMO_TEAM))
        team = team or create_team(SYSTEM, DEMO_TEAM)
        created, _ = launch(
            SYSTEM, name=DEMO_CONSTELLATION, kind="vrc", provider="local", team_id=team.id
        )
        click.echo(
            f"demo: launching a local vrc constellation: {base_url}constellations/{created.id}"
        )
        schedule_demo(team.id, created.id)
        click.echo(f"demo: once it is ready, the example controller runs a task: {base_url}runs")


@click.command()
@click.option(
    "--demo", is_flag=True, help="Also launch a local vrc constellation and a run for a demo team."
)
@reports_errors
def up(demo: bool) -> None:
    """Run CloudSim on this machine until Ctrl-C: Redis (if needed), workers, beat, web."""
    with app_context() as app:
        config: Config = app.config["CLOUDSIM"]
        migrate.upgrade(app)
        admin = ensure_first_admin(config.admin_email, config.admin_password)
        if admin is None:
            credentials = [
                f"log in as {config.admin_email}; forgot the password? "
                f"cloudsim user update {config.admin_email} --password-stdin"
            ]
        else:
            credentials = [f"created the first admin: {admin.user.email}"]
            if admin.generated_password:
                credentials.append(f"  password (shown once): {admin.generated_password}")
        if config.admin_token:
            # a team instance: its master's account and token, whatever happened to them here
            for restored in restore_master_access(config.admin_email, config.admin_token):
                click.echo(f"master access: {restored}")
    log_dir = config.instance_dir / "logs"
    supervisor = Supervisor(
        log=lambda line: click.echo(f"cloudsim up: {line}", err=True), log_dir=log_dir
    )
    shown = False
    try:
        for service, timeout in _services(config):
            click.echo(f"starting {service.name}")
            if service.name == "web":
                # Redis is up: a team instance serves no login but its master's until the
                # master has sent its current accounts (auth.master)
                note_started(config)
            supervisor.add(service, timeout)
        scheme = "https" if config.tls_cert else "http"
        if demo:
            _launch_demo(f"{scheme}://{config.bind}/")
        # What a person needs comes last, where the terminal leaves it.
        lines = [
            f"CloudSim is running at {scheme}://{config.bind}/  (Ctrl-C stops everything)",
            f"services' logs: {log_dir}/",
            *credentials,
        ]
        rule = "=" * max(len(line) for line in lines)
        click.echo("\n".join([rule, *lines, rule]))
        shown = True
        supervisor.run()
    except RuntimeError as exc:
        raise click.ClickException(str(exc)) from None
    finally:
        supervisor.stop()
        if not shown and admin is not None:
            click.echo("\n".join(credentials))  # a new admin's password is never lost
