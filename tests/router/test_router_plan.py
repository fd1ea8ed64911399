"""The router plan and its templates, without hosts: what it would install."""

from __future__ import annotations

from pathlib import Path

import pytest
from csrouter.config import RouterConfig
from csrouter.rules import queue_rules as daemon_queue_rules

from constellations.definition import load_kind
from constellations.plans import PLANS, PlanContext
from constellations.plans.base import Action, VpnMaterial
from constellations.plans.router import forward_rules, queue_rules, router
from provisioners.remote import pki
from provisioners.remote.operations import MachineTemplates, Operation

SUBNET = "10.215.7.0/24"


def context(vpn: VpnMaterial | None, wheelhouse: Path | None) -> PlanContext:
    kind = load_kind("vrc", set(PLANS))
    return PlanContext(
        constellation="alpha",
        team="team",
        kind=kind,
        machine=kind.machine("router"),
        subnet=SUBNET,
        addresses={m.name: m.address(SUBNET) for m in kind.machines},
        vpn=vpn,
        router_wheelhouse=wheelhouse,
    )


@pytest.fixture(scope="module")
def material() -> VpnMaterial:
    ca = pki.new_ca("alpha VPN CA")
    server = pki.issue_server(ca, "cloudsim-router")
    return VpnMaterial(ca.cert_pem, server.cert_pem, server.key_pem, pki.issue_crl(ca, []))


def test_the_plan_installs_the_rules_the_daemon_checks() -> None:
    daemon = daemon_queue_rules(RouterConfig(lan_subnet=SUBNET, vpn_network="10.9.0.0/24"))
    assert [(r.table, r.chain, list(r.args)) for r in daemon] == queue_rules(SUBNET, "10.9.0.0/24")


def test_without_vpn_material_the_router_only_forwards() -> None:
    names = [item.name for item in router(context(None, None))]
    assert not any("openvpn" in name.lower() or "csrouter" in name for name in names)


def test_a_vpn_needs_the_csrouter_wheelhouse(material: VpnMaterial) -> None:
    with pytest.raises(ValueError, match="wheelhouse"):
        router(context(material, None))


def test_the_vpn_plan_drops_everything_but_the_lan_for_clients(
    material: VpnMaterial, tmp_path: Path
) -> None:
    (tmp_path / "SHA256SUMS").write_text("")
    items = router(context(material, tmp_path))
    names = [item.name for item in items if isinstance(item, Operation)]
    rules = [" ".join(rule) for rule in forward_rules(context(material, tmp_path))]
    # the OCU reaches the field computers (everything) and sim's API ports, nothing else
    assert rules[1:5] == [
        "-i tun+ -d 10.215.7.52/32 -j ACCEPT",
        "-i tun+ -d 10.215.7.53/32 -j ACCEPT",
        "-i tun+ -d 10.215.7.51/32 -p tcp --dport 7700:7701 -j ACCEPT",
        "-i tun+ -j DROP",
    ]
    assert "iptables -t filter INPUT -i tun+ -j DROP" in names
    assert any("NFQUEUE --queue-num 0" in name and "-t raw" in name for name in names)
    assert any(isinstance(item, Action) and "OpenVPN" in item.name for item in items)
    assert names[-1] == "service openvpn-server@cloudsim (running, enabled)"
    assert isinstance(items[-1], Action) and "disconnect revoked" in items[-1].name


def test_the_client_template_inlines_the_bundle(material: VpnMaterial) -> None:
    text = MachineTemplates().render(
        "router/client.ovpn.j2",
        {
            "user": "operator@team.example",
            "constellation": "alpha",
            "file_name": "alpha.ovpn",
            "remote_host": "198.51.100.7",
            "remote_port": 1194,
            "server_name": "cloudsim-router",
            "ca_cert": material.ca_cert,
            "client_cert": "CERT",
            "client_key": "KEY",
        },
    )
    assert "remote 198.51.100.7 1194\n" in text and "<key>\nKEY\n</key>" in text
    assert "verify-x509-name cloudsim-router name" in text and "remote-cert-tls server" in text


def test_the_bundle_readme_lists_the_lan_machines() -> None:
    text = MachineTemplates().render(
        "router/vpn-bundle-README.txt.j2",
        {
            "user": "operator@team.example",
            "constellation": "alpha",
            "file_name": "alpha.ovpn",
            "remote_host": "198.51.100.7",
            "remote_port": 1194,
            "lan_addresses": {"sim": "10.0.0.51", "fc1": "10.0.0.52"},
            "field_computers": {"fc1": "10.0.0.52"},
            "account": "alice-7",
            "ssh_config": "Host alpha-fc1",
        },
    )
    assert "sudo openvpn --config alpha.ovpn" in text
    assert "ssh alice-7@10.0.0.52" in text and "Host alpha-fc1" in text
    assert "    sim      10.0.0.51\n    fc1      10.0.0.52\n" in text
