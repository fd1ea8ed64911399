"""FirewallRule validation and its translation into EC2 permissions, from data alone."""

import pytest

from provisioners.providers.ec2.permissions import (
    ALL_PROTOCOLS,
    ANY_IPV4,
    Permission,
    permission_params,
    rule_permission,
)
from provisioners.remote.firewall import FirewallRule

LAN = "10.0.0.0/24"
GROUP_IDS = {"router": "sg-router", "sim": "sg-sim"}


def test_valid_rule_keeps_its_fields_and_names_its_source_role() -> None:
    rule = FirewallRule(to_role="sim", protocol="tcp", ports=(22, 22), source="role:router")
    assert (rule.to_role, rule.protocol, rule.ports, rule.source_role) == (
        "sim",
        "tcp",
        (22, 22),
        "router",
    )
    assert FirewallRule("sim", "all", None, "lan").source_role is None


@pytest.mark.parametrize(
    ("arguments", "field"),
    [
        (("Sim", "tcp", (22, 22), "lan"), "to_role"),
        (("", "tcp", (22, 22), "lan"), "to_role"),
        (("sim", "sctp", (22, 22), "lan"), "protocol"),
        (("sim", "tcp", (23, 22), "lan"), "ports"),
        (("sim", "tcp", (0, 65536), "lan"), "ports"),
        (("sim", "tcp", [22, 22], "lan"), "ports"),
        (("sim", "tcp", (22, "22"), "lan"), "ports"),
        (("sim", "tcp", (True, 22), "lan"), "ports"),
        (("sim", "icmp", (8, 8), "lan"), "ports"),
        (("sim", "all", (1, 2), "lan"), "ports"),
        (("sim", "tcp", None, "internet"), "source"),
        (("sim", "tcp", None, "role:"), "source"),
        (("sim", "tcp", None, "role:Bad Role"), "source"),
        (("sim", "tcp", None, None), "source"),
    ],
)
def test_bad_rule_is_refused_naming_the_field(arguments: tuple[object, ...], field: str) -> None:
    with pytest.raises(ValueError, match=rf"^{field} "):
        FirewallRule(*arguments)  # type: ignore[arg-type]


def test_rule_is_frozen() -> None:
    rule = FirewallRule("sim", "udp", None, "any")
    with pytest.raises(AttributeError):
        rule.protocol = "tcp"  # type: ignore[misc]


@pytest.mark.parametrize(
    ("rule", "permission"),
    [
        (
            FirewallRule("sim", "tcp", (22, 22), "any"),
            Permission("tcp", 22, 22, cidr=ANY_IPV4),
        ),
        (FirewallRule("sim", "udp", None, "lan"), Permission("udp", 0, 65535, cidr=LAN)),
        (FirewallRule("sim", "icmp", None, "lan"), Permission("icmp", -1, -1, cidr=LAN)),
        (
            FirewallRule("sim", "all", None, "role:router"),
            Permission(ALL_PROTOCOLS, None, None, group_id="sg-router"),
        ),
    ],
)
def test_rule_becomes_one_permission(rule: FirewallRule, permission: Permission) -> None:
    assert rule_permission(rule, LAN, GROUP_IDS) == permission


def test_permissions_sharing_protocol_and_ports_become_one_ip_permission() -> None:
    params = permission_params(
        [
            Permission("tcp", 22, 22, cidr=LAN),
            Permission("tcp", 22, 22, group_id="sg-router"),
            Permission(ALL_PROTOCOLS, None, None, cidr=ANY_IPV4),
        ]
    )
    assert params == {
        "IpPermissions.1.IpProtocol": "-1",
        "IpPermissions.1.IpRanges.1.CidrIp": ANY_IPV4,
        "IpPermissions.2.IpProtocol": "tcp",
        "IpPermissions.2.FromPort": "22",
        "IpPermissions.2.ToPort": "22",
        "IpPermissions.2.IpRanges.1.CidrIp": LAN,
        "IpPermissions.2.Groups.1.GroupId": "sg-router",
    }
