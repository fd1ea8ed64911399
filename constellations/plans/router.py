"""What the router gets: forwarding between the VPN and the LAN, never public to LAN.

With VPN material (`ctx.vpn`) it also gets the team's OpenVPN server and csrouter, the
daemon that delays, counts and caps every OCU<->LAN packet (see router/README.md).
"""

from __future__ import annotations

import ipaddress
import shlex
from collections.abc import Sequence

from constellations.plans.base import Action, PlanContext, PlanItem, VpnMaterial
from constellations.plans.software import install_wheelhouse
from provisioners.remote.operations import (
    apply,
    directory,
    file,
    iptables_chain,
    iptables_rule,
    service,
    sysctl,
)
from provisioners.remote.ssh import Machine as Target
from provisioners.remote.ssh import SSHExecutor

FORWARD_CHAIN = "CLOUDSIM-FWD"
OCU_CHAIN = "CLOUDSIM-OCU"  # raw and mangle: OCU<->LAN packets to csrouter's queues
VPN_DEVICE = "tun-ocu"
VPN_INSTANCE = "cloudsim"
VPN_SERVICE = f"openvpn-server@{VPN_INSTANCE}"
VPN_SERVER_NAME = "cloudsim-router"  # the CN the app gives the router's certificate
OPENVPN_DIR = "/etc/openvpn/server"
PKI_DIR = f"{OPENVPN_DIR}/{VPN_INSTANCE}"
CSROUTER_VENV = "/opt/csrouter"
CSROUTER_CONFIG = "/etc/cloudsim/router.json"
CSROUTER_COMMAND = "/usr/local/sbin/csrouter"
CSROUTER_SERVICE = "csrouter"
UPLINK_QUEUE, DOWNLINK_QUEUE = 0, 1
SYSTEMD_DIR = "/etc/systemd/system"


def router(ctx: PlanContext) -> list[PlanItem]:
    """Forward VPN and LAN traffic; never let the public side into the LAN; run the VPN."""
    items: list[PlanItem] = [
        sysctl({"net.ipv4.ip_forward": 1}, templates=ctx.templates),
        iptables_chain(FORWARD_CHAIN),
        iptables_rule(
            FORWARD_CHAIN, ["-m", "conntrack", "--ctstate", "ESTABLISHED,RELATED", "-j", "ACCEPT"]
        ),
        iptables_rule(FORWARD_CHAIN, ["-i", "tun+", "-d", ctx.subnet, "-j", "ACCEPT"]),
        iptables_rule(FORWARD_CHAIN, ["-s", ctx.subnet, "-j", "ACCEPT"]),
        iptables_rule(FORWARD_CHAIN, ["-d", ctx.subnet, "-j", "DROP"]),
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


def vpn_firewall(ctx: PlanContext, vpn: VpnMaterial) -> list[PlanItem]:
    """Let VPN clients reach the LAN and nothing else (not the router, not the internet)."""
    return [
        iptables_rule(FORWARD_CHAIN, ["-i", "tun+", "-j", "DROP"]),
        iptables_rule(FORWARD_CHAIN, ["-o", "tun+", "-j", "DROP"]),
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
    """Install the OpenVPN server's configuration and PKI; restart it when they change."""
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
        },
    )
    drop_in = ctx.templates.render("router/openvpn-after-csrouter.conf.j2", {})
    operations = [
        # readable by `nobody`: OpenVPN re-reads the CRL at every connection after dropping root
        directory(PKI_DIR, mode=0o755),
        file(f"{PKI_DIR}/ca.crt", vpn.ca_cert),
        file(f"{PKI_DIR}/server.crt", vpn.server_cert),
        file(f"{PKI_DIR}/server.key", vpn.server_key, mode=0o600),
        *([file(f"{PKI_DIR}/crl.pem", vpn.crl)] if vpn.crl else []),
        file(f"{OPENVPN_DIR}/{VPN_INSTANCE}.conf", config),
        directory(f"{SYSTEMD_DIR}/{VPN_SERVICE}.service.d"),
        file(f"{SYSTEMD_DIR}/{VPN_SERVICE}.service.d/csrouter.conf", drop_in),
    ]
    return [
        # a restart drops every session, so a revoked certificate stops working at once
        _restart_on_change("OpenVPN configuration and PKI", operations, VPN_SERVICE),
        service(VPN_SERVICE, running=True, enabled=True),
    ]


def _restart_on_change(name: str, steps: Sequence[PlanItem], unit: str) -> Action:
    """Apply steps in order; if any changed, reload systemd and restart the unit if it runs."""

    def run(executor: SSHExecutor, target: Target) -> bool:
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
