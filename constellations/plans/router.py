"""What the router gets: forwarding between the VPN and the LAN, never public to LAN.

With VPN material (`ctx.vpn`) it also gets the team's OpenVPN server and csrouter, the
daemon that delays, counts and caps every OCU<->LAN packet (see router/README.md).
"""

from __future__ import annotations

import ipaddress
import shlex
from collections.abc import Callable, Sequence

from csrouter.config import DEFAULT_CONFIG_PATH, DOWNLINK_QUEUE, UPLINK_QUEUE

from constellations.plans.base import Action, PlanContext, PlanItem, VpnMaterial
from constellations.plans.common import match
from constellations.plans.software import install_wheelhouse
from provisioners.remote.operations import (
    apply,
    directory,
    file,
    iptables_chain,
    iptables_chain_exact,
    iptables_rule,
    service,
    sysctl,
)
from provisioners.remote.ssh import SSHExecutor, SSHTarget

FORWARD_CHAIN = "CLOUDSIM-FWD"
OCU_CHAIN = "CLOUDSIM-OCU"  # raw and mangle: OCU<->LAN packets to csrouter's queues
VPN_DEVICE = "tun-ocu"
VPN_INSTANCE = "cloudsim"
VPN_SERVICE = f"openvpn-server@{VPN_INSTANCE}"
VPN_SERVER_NAME = "cloudsim-router"  # the CN the app gives the router's certificate
OPENVPN_DIR = "/etc/openvpn/server"
PKI_DIR = f"{OPENVPN_DIR}/{VPN_INSTANCE}"
# root only (/run/openvpn-server is 0710 root): whoever holds it can disconnect anyone
VPN_MANAGEMENT_SOCKET = f"/run/openvpn-server/{VPN_INSTANCE}-management.sock"
VPN_STATE_DIR = "/var/lib/cloudsim/vpn"  # written by OpenVPN as nobody: the address pool
VPN_DISCONNECT_COMMAND = "/usr/local/sbin/cloudsim-vpn-disconnect"
CSROUTER_VENV = "/opt/csrouter"
CSROUTER_CONFIG = DEFAULT_CONFIG_PATH
CSROUTER_COMMAND = "/usr/local/sbin/csrouter"
CSROUTER_SERVICE = "csrouter"
SYSTEMD_DIR = "/etc/systemd/system"


def router(ctx: PlanContext) -> list[PlanItem]:
    """Forward VPN and LAN traffic; never let the public side into the LAN; run the VPN."""
    items: list[PlanItem] = [
        sysctl({"net.ipv4.ip_forward": 1}, templates=ctx.templates),
        iptables_chain_exact(FORWARD_CHAIN, forward_rules(ctx)),
        iptables_rule("FORWARD", ["-j", FORWARD_CHAIN], insert=True),
    ]
    if ctx.vpn is None:
        return items
    if ctx.router_wheelhouse is None:
        raise ValueError(f"{ctx.machine.name}: the VPN needs csrouter's wheelhouse")
    return (
        items
        + vpn_firewall(ctx, ctx.vpn)
        + ocu_queues(ctx, ctx.vpn)
        + csrouter(ctx)
        + vpn_server(ctx)
    )


def forward_rules(ctx: PlanContext) -> list[list[str]]:
    """Return the router's forward chain: the LAN goes out, VPN clients reach what the kind's
    `vpn` list allows (never sim's SSH), the public side never reaches the LAN."""
    vpn_access = [
        ["-i", "tun+", "-d", f"{address}/32", *match(rule), "-j", "ACCEPT"]
        for rule in (ctx.kind.vpn_access if ctx.vpn is not None else ())
        for address in ctx.addresses_of_role(rule.to_role)
    ]
    return [
        ["-m", "conntrack", "--ctstate", "ESTABLISHED,RELATED", "-j", "ACCEPT"],
        *vpn_access,
        ["-i", "tun+", "-j", "DROP"],
        ["-s", ctx.subnet, "-j", "ACCEPT"],
        ["-d", ctx.subnet, "-j", "DROP"],
        ["-o", "tun+", "-j", "DROP"],
    ]


def vpn_firewall(ctx: PlanContext, vpn: VpnMaterial) -> list[PlanItem]:
    """Keep VPN clients off the router itself; masquerade them into the LAN."""
    return [
        iptables_rule("INPUT", ["-i", "tun+", "-j", "DROP"], insert=True),
        # LAN machines accept their LAN only: OCU packets arrive from the router's address
        iptables_rule(
            "POSTROUTING",
            ["-s", vpn.network, "-d", ctx.subnet, "-j", "MASQUERADE"],
            table="nat",
        ),
    ]


def ocu_queues(ctx: PlanContext, vpn: VpnMaterial) -> list[PlanItem]:
    """Send OCU<->LAN packets to csrouter; without a reader the kernel drops them."""
    rules = queue_rules(ctx.subnet, vpn.network)
    return [
        *(iptables_chain(OCU_CHAIN, table=table) for table in sorted({t for t, _, _ in rules})),
        *(
            iptables_rule(chain, rule, table=table, insert=chain != OCU_CHAIN)
            for table, chain, rule in rules
        ),
    ]


def queue_rules(lan_subnet: str, vpn_network: str) -> list[tuple[str, str, list[str]]]:
    """Return csrouter's NFQUEUE rules as (table, chain, rule): the same the daemon restores.

    Packets that may start a flow are queued before connection tracking (raw), replies to
    the masqueraded OCU after it (mangle FORWARD); router/csrouter/rules.py says why.
    """
    uplink = ["-j", "NFQUEUE", "--queue-num", str(UPLINK_QUEUE)]
    downlink = ["-j", "NFQUEUE", "--queue-num", str(DOWNLINK_QUEUE)]
    not_local = ["-m", "addrtype", "!", "--dst-type", "LOCAL"]
    replies = ["-m", "conntrack", "--ctstate", "SNAT"]
    return [
        ("raw", OCU_CHAIN, ["-i", VPN_DEVICE, "-d", lan_subnet, *not_local, *uplink]),
        ("raw", OCU_CHAIN, ["-s", lan_subnet, "-d", vpn_network, *downlink]),
        ("raw", "PREROUTING", ["-j", OCU_CHAIN]),
        ("mangle", OCU_CHAIN, ["-s", lan_subnet, "-o", VPN_DEVICE, *replies, *downlink]),
        ("mangle", "FORWARD", ["-j", OCU_CHAIN]),
    ]


def csrouter(ctx: PlanContext) -> list[PlanItem]:
    """Install csrouter offline, configure it and keep it running under systemd."""
    assert ctx.router_wheelhouse is not None and ctx.vpn is not None
    render = ctx.templates.render
    config = {
        "lan_subnet": ctx.subnet,
        "vpn_network": ctx.vpn.network,
        "vpn_device": VPN_DEVICE,
        "uplink_queue": UPLINK_QUEUE,
        "downlink_queue": DOWNLINK_QUEUE,
    }
    unit = render(
        "router/csrouter.service.j2",
        {"venv": CSROUTER_VENV, "config_path": CSROUTER_CONFIG, "vpn_instance": VPN_INSTANCE},
    )
    operations = [
        directory("/etc/cloudsim", mode=0o755),
        file(CSROUTER_CONFIG, render("router/router.json.j2", {"config": config})),
        file(
            CSROUTER_COMMAND, render("router/csrouter.sh.j2", {"venv": CSROUTER_VENV}), mode=0o755
        ),
        file(f"{SYSTEMD_DIR}/{CSROUTER_SERVICE}.service", unit),
    ]
    install = install_wheelhouse(ctx.router_wheelhouse, CSROUTER_VENV, "cloudsim-router")
    return [
        # new code or configuration restarts a running daemon (it resumes the armed run)
        _restart_on_change(f"csrouter: {install.name}", [install, *operations], CSROUTER_SERVICE),
        service(CSROUTER_SERVICE, running=True, enabled=True),
    ]


def vpn_server(ctx: PlanContext) -> list[PlanItem]:
    """Install the OpenVPN server's configuration and PKI; restart it when they change.

    A new revocation list does not restart it: OpenVPN re-reads the list at every handshake,
    and the revoked clients are disconnected one by one over the management socket, so the
    team's other members stay connected (and keep their addresses).
    """
    vpn = ctx.vpn
    assert vpn is not None
    network = ipaddress.ip_network(vpn.network)
    lan = ipaddress.ip_network(ctx.subnet)
    config = ctx.templates.render(
        "router/openvpn-server.conf.j2",
        {
            "constellation": ctx.constellation,
            "port": vpn.port,
            "device": VPN_DEVICE,
            "network_address": network.network_address,
            "network_netmask": network.netmask,
            "lan_address": lan.network_address,
            "lan_netmask": lan.netmask,
            "pki_dir": PKI_DIR,
            "crl": bool(vpn.crl),
            "management_socket": VPN_MANAGEMENT_SOCKET,
            "state_dir": VPN_STATE_DIR,
        },
    )
    drop_in = ctx.templates.render("router/openvpn-after-csrouter.conf.j2", {})
    disconnect = ctx.templates.render(
        "router/vpn-disconnect.py.j2", {"management_socket": VPN_MANAGEMENT_SOCKET}
    )
    operations = [
        directory(VPN_STATE_DIR, mode=0o700, owner="nobody", group="nogroup"),
        file(f"{PKI_DIR}/ca.crt", vpn.ca_cert),
        file(f"{PKI_DIR}/server.crt", vpn.server_cert),
        file(f"{PKI_DIR}/server.key", vpn.server_key, mode=0o600),
        file(f"{OPENVPN_DIR}/{VPN_INSTANCE}.conf", config),
        directory(f"{SYSTEMD_DIR}/{VPN_SERVICE}.service.d"),
        file(f"{SYSTEMD_DIR}/{VPN_SERVICE}.service.d/csrouter.conf", drop_in),
    ]
    return [
        file(VPN_DISCONNECT_COMMAND, disconnect, mode=0o700),
        # readable by `nobody`: OpenVPN re-reads the CRL at every connection after dropping root
        directory(PKI_DIR, mode=0o755),
        # before the configuration: a (re)started server must already refuse revoked clients
        *([file(f"{PKI_DIR}/crl.pem", vpn.crl)] if vpn.crl else []),
        _restart_on_change("OpenVPN configuration and PKI", operations, VPN_SERVICE),
        service(VPN_SERVICE, running=True, enabled=True),
        Action("disconnect revoked VPN clients", _disconnect(vpn.revoked)),
    ]


def revocation(vpn: VpnMaterial) -> list[PlanItem]:
    """Return just what a revocation changes on a running router: the list, the sessions."""
    return [
        file(f"{PKI_DIR}/crl.pem", vpn.crl),
        Action("disconnect revoked VPN clients", _disconnect(vpn.revoked)),
    ]


def _disconnect(names: Sequence[str]) -> Callable[[SSHExecutor, SSHTarget], bool]:
    """Return an action that ends the sessions of these certificate names, if connected."""

    def run(executor: SSHExecutor, target: SSHTarget) -> bool:
        if not names:
            return False
        command = shlex.join([VPN_DISCONNECT_COMMAND, *names])
        result = executor.run(target, command, timeout=30)
        return "killed" in result.stdout

    return run


def _restart_on_change(name: str, steps: Sequence[PlanItem], unit: str) -> Action:
    """Apply steps in order; if any changed, reload systemd and restart the unit if it runs."""

    def run(executor: SSHExecutor, target: SSHTarget) -> bool:
        changed = False
        for step in steps:
            if isinstance(step, Action):
                changed = step.run(executor, target) or changed
            else:
                changed = apply(executor, target, step).changed or changed
        if changed:
            quoted = shlex.quote(unit)
            executor.run(
                target,
                f"systemctl daemon-reload && "
                f"if systemctl is-active --quiet {quoted}; then systemctl restart {quoted}; fi",
            )
        return changed

    return Action(name, run)
