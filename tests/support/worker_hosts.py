"""Worker machines for the scale-out test and benchmark: local hosts with CloudSim installed
from its source bundle (as the `cloudsim` kind installs it), running `cloudsim worker` against
the master's PostgreSQL, Redis and object store over the LAN.

The master's servers listen on loopback with passwords; relays at the public network's
gateway (the master's LAN address, as the hosts see it) carry the hosts' connections to them,
so nothing touches the machine's own network.
"""

from __future__ import annotations

import json
import secrets
import shlex
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path

from drcsim.rundir import COMMANDS, META, SCORE, STATE
from libcloud.compute.base import Node, NodeAuthSSHKey

from cloudsim.competition.artifacts import run_dir
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.launched_constellations.keys import (
    SSH_KEY_NAME,
    KeyPair,
    constellation_secret,
    generate_keypair,
)
from cloudsim.models import Constellation, ConstellationState, Machine, SecretKind
from cloudsim.providers.service import open_provider
from constellations.plans.roles import CLOUDSIM_ROOT, CLOUDSIM_VENV
from constellations.plans.software import (
    REMOTE_ROOT,
    build_source_bundle,
    distribution_source,
    install_source_bundle,
)
from provisioners.remote.ssh import HostKeys, SSHExecutor, SSHTarget
from tests.support.lightweight_runs import SCORE_LOG, SYSTEMCTL
from tests.support.relay import relay
from tests.support.servers import PostgresServer, RedisServer

WORKER_ENV = "/etc/cloudsim/worker.env"
WORKER_LOG = "/var/log/cloudsim-worker.log"
WORKER_INSTANCE = "/var/lib/cloudsim"


@dataclass(frozen=True)
class Host:
    """A local host and how the master's machine logs in to it."""

    node: Node
    keys: KeyPair
    target: SSHTarget

    def run(self, command: str, timeout: float = 120) -> str:
        """Run a command on the host; return its output."""
        with SSHExecutor(HostKeys()) as executor:
            return executor.run(self.target, command, timeout=timeout).stdout

    @property
    def address(self) -> str:
        """Return the host's address on the LAN the gateway is on."""
        return str(self.node.public_ips[0])


@dataclass(frozen=True)
class MasterServers:
    """The master's PostgreSQL, Redis and object store, and the settings that reach them from
    the master itself (`master`, Config fields) and from the LAN (`remote`, CLOUDSIM_* values)."""

    master: dict[str, object]
    remote: dict[str, str]
    ports: tuple[int, ...]
    password: str


@contextmanager
def master_servers(folder: Path, store_port: int, gateway: str) -> Iterator[MasterServers]:
    """Start a PostgreSQL and a Redis that need a password; name an S3 store at store_port."""
    password = secrets.token_urlsafe(18)
    postgres = PostgresServer(password=password)
    try:
        redis = RedisServer(folder / "master-redis", password=password)
    except BaseException:
        postgres.stop()
        raise
    try:
        database = postgres.create_login_database(f"cloudsim_{secrets.token_hex(4)}")
        container = f"logs-{secrets.token_hex(4)}"
        options = {"secure": False, "port": store_port}
        master: dict[str, object] = {
            "database_url": database,
            "redis_url": redis.url(0),
            "artifact_store": "s3",
            "artifact_container": container,
            "artifact_key": "scaleout-key",
            "artifact_secret": password,
            "artifact_options": {**options, "host": "127.0.0.1"},
        }
        remote = {
            "CLOUDSIM_DATABASE_URL": database.replace("@127.0.0.1:", f"@{gateway}:"),
            "CLOUDSIM_REDIS_URL": redis.url(0, host=gateway),
            "CLOUDSIM_ARTIFACT_STORE": "s3",
            "CLOUDSIM_ARTIFACT_CONTAINER": container,
            "CLOUDSIM_ARTIFACT_KEY": "scaleout-key",
            "CLOUDSIM_ARTIFACT_SECRET": password,
            "CLOUDSIM_ARTIFACT_OPTIONS": json.dumps({**options, "host": gateway}),
        }
        yield MasterServers(master, remote, (postgres.port, redis.port, store_port), password)
    finally:
        redis.stop()
        postgres.stop()


@contextmanager
def reachable_from_lan(switch: str, gateway: str, ports: tuple[int, ...]) -> Iterator[None]:
    """Relay each port at the gateway (inside the public switch namespace) to loopback."""
    with ExitStack() as stack:
        for port in ports:
            stack.enter_context(relay(switch, (gateway, port), port))
        yield


def boot_hosts(config: Config, network: str, names: dict[str, str | None]) -> list[Host]:
    """Boot hosts (name: init, None for the provider's default), each with an address on the
    public LAN (where the gateway is)."""
    driver = open_provider("local", config).driver
    lan = driver.ex_create_network(network)  # type: ignore[attr-defined]

    def boot(name: str) -> Host:
        keys = generate_keypair(name)
        node = driver.create_node(  # type: ignore[call-arg]
            name,
            auth=NodeAuthSSHKey(keys.public),
            ex_network=lan,
            ex_public=True,
            ex_init=names[name],
        )
        route = driver.ex_ssh_route(node)  # type: ignore[attr-defined]
        target = SSHTarget(
            name=name,
            host=route.host,
            private_key=keys.private,
            proxy_command=list(route.proxy_command or ()),
        )
        return Host(node, keys, target)

    with ThreadPoolExecutor(max_workers=4) as pool:
        return list(pool.map(boot, list(names)))


def cloudsim_bundle(cache: Path, python: str) -> Path:
    """Return CloudSim's source bundle, as the `cloudsim` kind's launch builds it (cached)."""
    members = [distribution_source("drcsim"), distribution_source("cloudsim-router")]
    return build_source_bundle(distribution_source("cloudsim"), cache, python, members)


def install_cloudsim(host: Host, bundle: Path) -> None:
    """Install CloudSim on the host as the `cloudsim` kind's plan does: the bundle, offline."""
    with SSHExecutor(HostKeys()) as executor:
        install_source_bundle(bundle, CLOUDSIM_ROOT, CLOUDSIM_VENV).run(executor, host.target)


def worker_env(config: Config, servers: MasterServers, bundle: Path) -> dict[str, str]:
    """Return a worker machine's settings: the master's database, Redis, store and keys."""
    return {
        # eight engineers' tests share two cores (as hosts_config's sim_min_rtf says)
        "CLOUDSIM_SIM_MIN_RTF": str(config.sim_min_rtf),
        **servers.remote,
        "CLOUDSIM_INSTANCE_DIR": WORKER_INSTANCE,
        "CLOUDSIM_ENCRYPTION_KEYS": ",".join(config.encryption_keys),
        "CLOUDSIM_SECRET_KEY": config.secret_key,
        "CLOUDSIM_JOB_LEASE_SECONDS": str(config.job_lease_seconds),
        "CLOUDSIM_JOB_STALL_SECONDS": str(config.job_stall_seconds),
        "CLOUDSIM_WORKER_CONCURRENCY": "2",
        "CLOUDSIM_LOG_LEVEL": "INFO",
        # no internet on the machine: wheels come from those CloudSim was installed with
        "PIP_NO_INDEX": "1",
        "PIP_FIND_LINKS": f"{REMOTE_ROOT}/{bundle.name}",
    }


def start_worker(host: Host, env: dict[str, str]) -> int:
    """Write the settings (0600) and start `cloudsim worker` on the host, detached; return
    its PID."""
    lines = "".join(f"{key}={shlex.quote(value)}\n" for key, value in sorted(env.items()))
    host.run(
        f"mkdir -p /etc/cloudsim && umask 077 && printf '%s' {shlex.quote(lines)} > {WORKER_ENV}"
    )
    pid = host.run(
        f"set -a && . {WORKER_ENV} && set +a && "
        f"setsid nohup {CLOUDSIM_VENV}/bin/cloudsim worker > {WORKER_LOG} 2>&1 < /dev/null & "
        "echo $!"
    )
    return int(pid.strip())


def stop_worker(host: Host, pid: int) -> None:
    """Stop the worker by its PID (Celery's warm shutdown) and wait until it is gone."""
    host.run(
        f"kill -TERM {pid} 2>/dev/null; "
        f"timeout 60 sh -c 'while kill -0 {pid} 2>/dev/null; do sleep 0.2; done'; true",
        timeout=90,
    )


def sim_stand_in(host: Host) -> None:
    """Make the host answer as a run's simulator machine does (see lightweight_runs)."""
    host.run(
        f"printf '%s' {shlex.quote(SYSTEMCTL)} > /usr/local/bin/systemctl"
        " && chmod +x /usr/local/bin/systemctl"
    )


def write_run_logs(host: Host, run_ids: list[int], state_bytes: int = 1 << 20) -> None:
    """Leave on the stand-in sim the logs a simulator leaves in each run's folder: the score
    log, and placeholders of the others a stop job must collect (the state log random)."""
    steps = []
    for run_id in run_ids:
        folder = shlex.quote(run_dir(run_id))
        steps.append(
            f"mkdir -p {folder} && cd {folder} && printf '%s' {shlex.quote(SCORE_LOG)} > {SCORE}"
            f" && echo '{{}}' > {META} && : > {COMMANDS}"
            f" && head -c {state_bytes} /dev/urandom > {STATE}"
        )
    host.run(" && ".join(f"({step})" for step in steps))


def server_inventory(server: Host, network_cidr: str) -> list[dict[str, object]]:
    """Return the servers provider's inventory of one existing server, reached at its LAN
    address (no proxy): from a worker machine, as from any machine in its data centre."""
    return [
        {
            "name": server.node.name,
            "address": server.address,
            "private_ip": server.node.private_ips[0],
            "public_ip": server.address,
            "network": "dc-lan",
            "cidr": network_cidr,
            "private_key": str(server.keys.private),
            "capabilities": ["gpu"],
        }
    ]


def sim_constellation(team_id: int, name: str, sim: Host) -> Constellation:
    """Add a ready constellation whose sim is the host, reached at its LAN address (no proxy):
    a worker machine reaches it as a worker in a data centre reaches its machines."""
    constellation = Constellation(
        name=name,
        kind="simple",
        provider="local",
        team_id=team_id,
        state=ConstellationState.READY,
    )
    db.session.add(constellation)
    db.session.flush()
    private = str(sim.keys.private)
    constellation_secret(constellation, SSH_KEY_NAME, SecretKind.SSH_PRIVATE_KEY, lambda: private)
    db.session.add(
        Machine(
            constellation_id=constellation.id,
            name="sim",
            role="sim",
            private_ip=sim.address,
            ssh_route={"host": sim.address, "user": "root", "port": 22},
        )
    )
    db.session.commit()
    return constellation
