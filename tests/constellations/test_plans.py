"""Deploy plans from data: what each role gets, without any SSH."""

from __future__ import annotations

from constellations.definition import load_kind
from constellations.plans import PLANS, PlanContext, firewall
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
    return [op.name for op in firewall(ctx) if isinstance(op, Operation)]


def test_sim_accepts_only_the_lan_then_drops() -> None:
    rules = _rules(_context("sim"))
    assert rules[1:3] == [
        "iptables -t filter CLOUDSIM-IN -i lo -j ACCEPT",
        "iptables -t filter CLOUDSIM-IN -m conntrack --ctstate ESTABLISHED,RELATED -j ACCEPT",
    ]
    assert "iptables -t filter CLOUDSIM-IN -s 10.211.9.0/24 -j ACCEPT" in rules
    assert not any("--dport 22" in rule and "-s" not in rule for rule in rules)
    assert rules[-2:] == [
        "iptables -t filter CLOUDSIM-IN -j DROP",
        "iptables -t filter INPUT -j CLOUDSIM-IN",
    ]


def test_router_accepts_ssh_and_vpn_from_anywhere() -> None:
    rules = _rules(_context("router"))
    assert "iptables -t filter CLOUDSIM-IN -p tcp --dport 22 -j ACCEPT" in rules
    assert "iptables -t filter CLOUDSIM-IN -p udp --dport 1194 -j ACCEPT" in rules


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
    assert "iptables -t filter CLOUDSIM-FWD -i tun+ -d 10.211.9.0/24 -j ACCEPT" in names
    assert names.index("iptables -t filter CLOUDSIM-FWD -s 10.211.9.0/24 -j ACCEPT") < (
        names.index("iptables -t filter CLOUDSIM-FWD -d 10.211.9.0/24 -j DROP")
    )
