"""Deploy plans from data: what each role gets, without any SSH."""

from __future__ import annotations

from constellations.definition import load_kind
from constellations.plans import PLANS, PlanContext, firewall
from constellations.plans.common import host_firewall_rules
from constellations.plans.router import forward_rules
from provisioners.remote.facts.files import PathState
from provisioners.remote.operations import Operation

SUBNET = "10.211.9.0/24"


def _context(machine: str) -> PlanContext:
    kind = load_kind("vrc", set(PLANS))
    return PlanContext(
        constellation="team7",
        team="Team 7",
        kind=kind,
        machine=kind.machine(machine),
        subnet=SUBNET,
        addresses={m.name: m.address(SUBNET) for m in kind.machines},
    )


def _rules(ctx: PlanContext) -> list[str]:
    return [" ".join(rule) for rule in host_firewall_rules(ctx)]


def test_the_firewall_chain_is_rewritten_exactly_and_jumped_to() -> None:
    names = [op.name for op in firewall(_context("sim")) if isinstance(op, Operation)]
    assert names == [
        f"iptables -t filter CLOUDSIM-IN: {len(_rules(_context('sim')))} rules",
        "iptables -t filter INPUT -j CLOUDSIM-IN",
    ]


def test_sim_accepts_ssh_from_the_router_and_its_api_from_the_lan_only() -> None:
    rules = _rules(_context("sim"))
    assert rules[:2] == [
        "-i lo -j ACCEPT",
        "-m conntrack --ctstate ESTABLISHED,RELATED -j ACCEPT",
    ]
    assert "-s 10.211.9.50/32 -p tcp --dport 22 -j ACCEPT" in rules  # CloudSim's path
    assert "-s 10.211.9.0/24 -p tcp --dport 7700:7701 -j ACCEPT" in rules
    assert not any("--dport 22" in rule and "10.211.9.0/24" in rule for rule in rules)
    assert not any(rule == "-s 10.211.9.0/24 -j ACCEPT" for rule in rules)
    assert rules[-1] == "-j DROP"


def test_router_accepts_ssh_from_outside_the_lan_and_vpn_from_anywhere() -> None:
    rules = _rules(_context("router"))
    assert "! -s 10.211.9.0/24 -p tcp --dport 22 -j ACCEPT" in rules
    assert "-p udp --dport 1194 -j ACCEPT" in rules


def test_field_computers_accept_the_whole_lan() -> None:
    assert "-s 10.211.9.0/24 -j ACCEPT" in _rules(_context("fc1"))


def test_lan_machines_route_through_the_router_and_know_their_peers() -> None:
    plan = PLANS["common"](_context("fc1"))
    names = [item.name for item in plan]
    assert "default route via 10.211.9.50" in names
    hosts = plan[1].steps(PathState.absent())[0]  # no /etc/hosts yet: the file is uploaded
    assert b"10.211.9.51\tsim" in hosts.content and b"team7-fc1" in hosts.content
    router_plan = [item.name for item in PLANS["common"](_context("router"))]
    assert not any(name.startswith("default route") for name in router_plan)


def test_router_forwards_vpn_and_lan_but_drops_public_to_lan() -> None:
    names = [item.name for item in PLANS["router"](_context("router"))]
    assert names[0].startswith("sysctl net.ipv4.ip_forward=1")
    rules = [" ".join(rule) for rule in forward_rules(_context("router"))]
    assert rules.index("-s 10.211.9.0/24 -j ACCEPT") < rules.index("-d 10.211.9.0/24 -j DROP")
    assert not any("tun+" in rule and "ACCEPT" in rule for rule in rules)  # no VPN here
