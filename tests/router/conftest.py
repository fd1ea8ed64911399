"""A router lab on local hosts: router (LAN + public), sim (LAN), OCU (public), VPN up."""

from __future__ import annotations

import functools
import json
import os
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, TypeVar

import pytest
from libcloud.compute.base import Node, NodeAuthSSHKey

from cloudsim.launched_constellations.keys import generate_keypair
from constellations.definition import ConstellationKind, load_kind
from constellations.plans import PLANS, PlanContext, apply_plan, firewall
from constellations.plans.base import VpnMaterial
from constellations.plans.router import VPN_SERVER_NAME, router
from constellations.plans.software import build_wheelhouse, distribution_source
from provisioners.providers.local.driver import LocalNodeDriver
from provisioners.remote import pki
from provisioners.remote.firewall import SOURCE_ANY, SOURCE_LAN, FirewallRule
from provisioners.remote.operations import MachineTemplates
from provisioners.remote.ssh import CommandResult, ConnectPolicy, HostKeys, SSHExecutor, SSHTarget

PREFIX = f"crt{os.getpid() % 100000}"
SUBNET_POOL = "10.215.0.0/16"
PUBLIC_CIDR = "198.18.15.0/24"
VPN_NETWORK = "10.8.0.0/24"
TRAFFIC_SCRIPT = Path(__file__).with_name("traffic.py")
REMOTE_TRAFFIC = "/root/traffic.py"
T = TypeVar("T")


def wait_for(check: Callable[[], T | None], timeout: float, what: str, pause: float = 0.2) -> T:
    """Poll until check returns something truthy; fail naming what never happened."""
    deadline = time.monotonic() + timeout
    while True:
        value = check()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout:.0f} s waiting for {what}")
        time.sleep(pause)


@dataclass
class RouterLab:
    """The hosts, an SSH executor to them and the VPN's PKI."""

    driver: LocalNodeDriver
    executor: SSHExecutor
    targets: dict[str, SSHTarget]
    nodes: dict[str, Node]
    router_context: PlanContext
    sim_context: PlanContext
    ca: pki.CertificateAuthority
    clients: dict[str, pki.IssuedCertificate] = field(default_factory=dict)
    crls: dict[tuple[int, ...], str] = field(default_factory=dict)

    def ip(self, name: str) -> str:
        """Return a host's LAN (private) address."""
        return str(self.nodes[name].private_ips[0])

    def public_ip(self, name: str) -> str:
        """Return a host's public address."""
        return str(self.nodes[name].public_ips[0])

    def run(self, name: str, command: str, *, check: bool = True, timeout: float = 60) -> str:
        """Run a command on a host; return its stdout."""
        return self.executor.run(self.targets[name], command, check=check, timeout=timeout).stdout

    def result(self, name: str, command: str, timeout: float = 60) -> CommandResult:
        """Run a command on a host that may fail; return the whole result."""
        return self.executor.run(self.targets[name], command, check=False, timeout=timeout)

    def csrouter(self, *args: str) -> dict[str, Any]:
        """Run a csrouter control command on the router and return its JSON."""
        return json.loads(self.run("router", shlex.join(["csrouter", *args, "--json"])))

    def apply_router(self, vpn: VpnMaterial) -> int:
        """Apply the router plan with this VPN material; return how many items changed."""
        self.router_context = replace(self.router_context, vpn=vpn)
        return apply_plan(self.executor, self.targets["router"], router(self.router_context))

    def vpn_material(self, revoked: list[int]) -> VpnMaterial:
        """Return the router's VPN material with a CRL revoking these serials."""
        server = self.clients["server"]
        # one CRL per revocation list: a re-issued one differs (its dates) and is pushed again
        key = tuple(sorted(revoked))
        self.crls.setdefault(key, pki.issue_crl(self.ca, key))
        return VpnMaterial(
            ca_cert=self.ca.cert_pem,
            server_cert=server.cert_pem,
            server_key=server.key_pem,
            crl=self.crls[key],
            network=VPN_NETWORK,
            revoked=tuple(c.common_name for c in self.clients.values() if c.serial in key),
        )

    def start_client(self, user: str) -> None:
        """Write a client bundle rendered from the template on the OCU and start it."""
        client = self.clients[user]
        config = MachineTemplates().render(
            "router/client.ovpn.j2",
            {
                "user": client.common_name,
                "constellation": PREFIX,
                "file_name": f"{user}.conf",
                "remote_host": self.public_ip("router"),
                "remote_port": 1194,
                "server_name": VPN_SERVER_NAME,
                "ca_cert": self.ca.cert_pem,
                "client_cert": client.cert_pem,
                "client_key": client.key_pem,
            },
        )
        self.executor.put_file(
            self.targets["ocu"], config.encode(), f"/etc/openvpn/client/{user}.conf", mode=0o600
        )
        self.run("ocu", f"systemctl start openvpn-client@{shlex.quote(user)}")

    def stop_client(self, user: str) -> None:
        """Stop a VPN client on the OCU."""
        self.run("ocu", f"systemctl stop openvpn-client@{shlex.quote(user)}")

    def ping(self, source: str, address: str, count: int = 1, wait: float = 1) -> CommandResult:
        """Ping from a host; the result says whether any reply came."""
        return self.result(
            source, f"ping -n -q -c {count} -i 0.2 -W {wait:g} {shlex.quote(address)}", timeout=30
        )

    def start_receiver(self, host: str, port: int, timeout: float, idle: float) -> str:
        """Start a UDP counter on a host in the background; return its output file."""
        out = f"/root/recv-{port}-{time.monotonic_ns()}.out"
        script = f"python3 {REMOTE_TRAFFIC} recv {port} {timeout:g} {idle:g}"
        self.run(host, f"setsid {script} > {out} 2>&1 < /dev/null &")
        wait_for(lambda: "listening" in self.run(host, f"cat {out}"), 10, f"receiver on {host}")
        return out

    def start_echo(self, host: str, port: int, idle: float) -> None:
        """Start a UDP echo on a host in the background (it ends after `idle` s of silence)."""
        out = f"/root/echo-{port}-{time.monotonic_ns()}.out"
        script = f"python3 {REMOTE_TRAFFIC} echo {port} {idle:g}"
        self.run(host, f"setsid {script} > {out} 2>&1 < /dev/null &")
        wait_for(lambda: "listening" in self.run(host, f"cat {out}"), 10, f"echo on {host}")

    def received(self, host: str, out: str, timeout: float = 30) -> dict[str, int]:
        """Wait for a UDP counter's result."""
        lines = wait_for(
            lambda: [ln for ln in self.run(host, f"cat {out}").splitlines() if ln.startswith("{")],
            timeout,
            f"the receiver's count on {host}",
        )
        return dict(json.loads(lines[0]))

    def send_udp(self, host: str, to: str, port: int, count: int, size: int, pps: int) -> None:
        """Send UDP datagrams from a host, paced."""
        self.run(host, f"python3 {REMOTE_TRAFFIC} send {to} {port} {count} {size} {pps}")


@pytest.fixture(scope="session")
def lab() -> Iterator[RouterLab]:
    """Boot router, sim and OCU, apply the plans, connect the OCU; destroy it all after."""
    if os.geteuid() != 0:
        pytest.skip("local hosts need root")
    scratch = Path(tempfile.mkdtemp(prefix=f"{PREFIX}-"))
    driver = LocalNodeDriver(
        state_dir=str(scratch / "state"),
        prefix=PREFIX,
        subnet_pool=SUBNET_POOL,
        public_cidr=PUBLIC_CIDR,
    )
    executor = SSHExecutor(HostKeys(), connect_policy=ConnectPolicy(deadline=60))
    try:
        yield _build_lab(driver, executor, scratch)
    finally:
        tear_down(driver, executor, scratch)
    left = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout
    assert PREFIX not in left, f"namespaces left behind: {left}"


def tear_down(driver: LocalNodeDriver, executor: SSHExecutor, scratch: Path) -> None:
    """Close the connections, destroy every host and network, remove the scratch folder.

    Every step is tried even when an earlier one fails (a broken SSH proxy must not leak
    hosts); the first failure is raised at the end.
    """
    failures: list[Exception] = []

    def attempt(action: Callable[[], object]) -> None:
        try:
            action()
        except Exception as exc:  # collected and raised below, after the other steps
            failures.append(exc)

    attempt(executor.close)
    for node in driver.list_nodes():
        attempt(functools.partial(driver.destroy_node, node))
    for network in driver.ex_list_networks():
        attempt(functools.partial(driver.ex_destroy_network, network))
    attempt(lambda: shutil.rmtree(scratch))
    if failures:
        raise failures[0]


def lab_kind() -> ConstellationKind:
    """The vrc kind with its sim open to the OCU and the LAN: this lab's "sim" stands for any
    LAN machine the OCU talks to (the vrc seal itself is checked in tests/fleet)."""
    kind = load_kind("vrc", set(PLANS))
    everything = FirewallRule(to_role="sim", protocol="all", ports=None, source=SOURCE_LAN)
    return replace(
        kind,
        firewall=(*kind.firewall, everything),
        vpn_access=(*kind.vpn_access, replace(everything, source=SOURCE_ANY)),
    )


def _build_lab(driver: LocalNodeDriver, executor: SSHExecutor, scratch: Path) -> RouterLab:
    kind = lab_kind()
    lan = driver.ex_create_network(f"{PREFIX}-lan")
    router_ip = kind.machine("router").address(lan.cidr)
    # the LAN's default gateway is the router, as the common plan would make it
    driver.ex_destroy_network(lan)
    lan = driver.ex_create_network(f"{PREFIX}-lan", lan.cidr, router_ip)
    home = driver.ex_create_network(f"{PREFIX}-home")
    keys = generate_keypair("cloudsim-router-tests")
    auth = NodeAuthSSHKey(keys.public)
    wheelhouse = build_wheelhouse(
        distribution_source("cloudsim-router"), scratch / "wheelhouse", sys.executable
    )
    nodes = {
        "router": driver.create_node(
            f"{PREFIX}-router", auth=auth, ex_network=lan, ex_private_ip=router_ip, ex_public=True
        ),
        "sim": driver.create_node(
            f"{PREFIX}-sim",
            auth=auth,
            ex_network=lan,
            ex_private_ip=kind.machine("sim").address(lan.cidr),
        ),
        "ocu": driver.create_node(f"{PREFIX}-ocu", auth=auth, ex_network=home, ex_public=True),
    }
    targets = {
        name: SSHTarget(
            name=name,
            host=str(node.private_ips[0]),
            private_key=keys.private,
            proxy_command=node.extra["ssh_proxy_command"],
        )
        for name, node in nodes.items()
    }
    addresses = {m.name: m.address(lan.cidr) for m in kind.machines}

    def context(name: str) -> PlanContext:
        return PlanContext(
            constellation=PREFIX,
            team="team",
            kind=kind,
            machine=kind.machine(name),
            subnet=lan.cidr,
            addresses=addresses,
            router_wheelhouse=wheelhouse,
        )

    ca = pki.new_ca(f"{PREFIX} VPN CA")
    lab = RouterLab(driver, executor, targets, nodes, context("router"), context("sim"), ca)
    lab.clients = {
        "server": pki.issue_server(ca, VPN_SERVER_NAME),
        "ocu": pki.issue_client(ca, "operator@team.example"),
        "spare": pki.issue_client(ca, "spare@team.example"),
        "departed": pki.issue_client(ca, "departed@team.example"),
    }
    for name in ("router", "sim"):
        apply_plan(executor, targets[name], firewall(context(name)))
    lab.apply_router(lab.vpn_material(revoked=[]))
    for name in ("sim", "ocu"):
        executor.put_file(targets[name], TRAFFIC_SCRIPT, REMOTE_TRAFFIC)
    lab.start_client("ocu")
    wait_for(lambda: lab.ping("ocu", lab.ip("sim")).ok, 60, "the OCU to reach the sim over the VPN")
    return lab
