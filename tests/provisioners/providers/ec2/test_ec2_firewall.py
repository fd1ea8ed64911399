"""Firewalls as security groups on moto's EC2: applied, re-applied, reconciled, refused."""

from collections.abc import Iterator, Sequence
from typing import Any

import pytest

from provisioners.providers.ec2.driver import CloudSimEC2NodeDriver
from provisioners.providers.ec2.errors import InvalidRequestError
from provisioners.providers.ec2.networks import EC2ConstellationNetwork
from provisioners.remote.firewall import FirewallRule

ROLES = ["router", "sim", "fc1", "fc2"]
LAN = "10.0.0.0/24"
# A vrc-like firewall: the router is the only door; sim and field computers talk on the LAN.
VRC_RULES = [
    FirewallRule("router", "udp", (1194, 1194), "any"),
    FirewallRule("router", "tcp", (22, 22), "any"),
    FirewallRule("router", "all", None, "lan"),
    FirewallRule("sim", "all", None, "lan"),
    FirewallRule("fc1", "tcp", None, "role:sim"),
    FirewallRule("fc1", "icmp", None, "lan"),
    FirewallRule("fc2", "tcp", (11311, 11311), "role:sim"),
    FirewallRule("fc2", "tcp", (11311, 11311), "role:fc1"),
]

Rule = tuple[str, int | None, int | None, str]


@pytest.fixture
def network(driver: CloudSimEC2NodeDriver, network_name: str) -> Iterator[EC2ConstellationNetwork]:
    network = driver.ex_create_network(network_name, LAN)
    yield network
    driver.ex_destroy_network(network)


def ingress_by_role(
    driver: CloudSimEC2NodeDriver, group_ids: dict[str, str]
) -> dict[str, set[Rule]]:
    """Read each role's ingress through libcloud's own security group listing."""
    role_of = {group_id: role for role, group_id in group_ids.items()}
    groups = driver.ex_get_security_groups(group_ids=list(group_ids.values()))
    found: dict[str, set[Rule]] = {}
    for group in groups:
        rules: set[Rule] = set()
        for rule in group.ingress_rules:
            ports = (_port(rule["from_port"]), _port(rule["to_port"]))
            for cidr in rule["cidr_ips"]:
                rules.add((rule["protocol"], *ports, cidr))
            for pair in rule["group_pairs"]:
                rules.add((rule["protocol"], *ports, "role:" + role_of[pair["group_id"]]))
        found[role_of[group.id]] = rules
    return found


def _port(value: Any) -> int | None:
    return None if value is None else int(value)


def apply(
    driver: CloudSimEC2NodeDriver,
    network: EC2ConstellationNetwork,
    rules: Sequence[FirewallRule],
) -> tuple[dict[str, str], list[str]]:
    """Apply rules and return the group ids and the EC2 actions that changed something."""
    sent: list[str] = []
    call = driver._api.call

    def recording_call(action: str, params: Any = None) -> Any:
        if not action.startswith("Describe"):
            sent.append(action)
        return call(action, params)

    driver._api.call = recording_call  # type: ignore[method-assign]
    try:
        return driver.ex_apply_firewall(network, rules, ROLES), sent
    finally:
        del driver._api.call


def test_firewall_becomes_one_security_group_per_role_with_the_rules_as_ingress(
    driver: CloudSimEC2NodeDriver, network: EC2ConstellationNetwork
) -> None:
    group_ids, _ = apply(driver, network, VRC_RULES)

    assert sorted(group_ids) == sorted(ROLES)
    groups = driver.ex_get_security_groups(group_ids=list(group_ids.values()))
    assert sorted(group.name for group in groups) == sorted(f"{network.name}-{r}" for r in ROLES)
    for group in groups:
        assert group.extra["vpc_id"] == network.id
        assert group.extra["tags"]["cloudsim:network"] == network.name
        assert group.egress_rules == [
            {
                "protocol": "-1",
                "from_port": None,
                "to_port": None,
                "group_pairs": [],
                "cidr_ips": ["0.0.0.0/0"],
            }
        ]
    assert ingress_by_role(driver, group_ids) == {
        "router": {
            ("udp", 1194, 1194, "0.0.0.0/0"),
            ("tcp", 22, 22, "0.0.0.0/0"),
            ("-1", None, None, LAN),
        },
        "sim": {("-1", None, None, LAN)},
        "fc1": {("tcp", 0, 65535, "role:sim"), ("icmp", -1, -1, LAN)},
        "fc2": {("tcp", 11311, 11311, "role:sim"), ("tcp", 11311, 11311, "role:fc1")},
    }


def test_reapplying_the_same_rules_changes_nothing(
    driver: CloudSimEC2NodeDriver, network: EC2ConstellationNetwork
) -> None:
    group_ids, first_actions = apply(driver, network, VRC_RULES)
    before = ingress_by_role(driver, group_ids)

    again_ids, again_actions = apply(driver, network, VRC_RULES)

    assert "CreateSecurityGroup" in first_actions
    assert again_actions == []
    assert again_ids == group_ids
    assert ingress_by_role(driver, group_ids) == before


def test_changed_rules_are_reconciled(
    driver: CloudSimEC2NodeDriver, network: EC2ConstellationNetwork
) -> None:
    group_ids, _ = apply(driver, network, VRC_RULES)
    changed = [
        FirewallRule("router", "udp", (1194, 1194), "any"),
        FirewallRule("router", "tcp", (22, 22), "lan"),  # was "any"
        FirewallRule("sim", "all", None, "lan"),
        FirewallRule("sim", "udp", (5000, 5010), "role:router"),  # new
        FirewallRule("fc1", "tcp", None, "role:sim"),
    ]  # the router's LAN rule, fc1's icmp and both fc2 rules are gone

    new_ids, actions = apply(driver, network, changed)

    assert new_ids == group_ids
    assert "CreateSecurityGroup" not in actions
    assert ingress_by_role(driver, group_ids) == {
        "router": {("udp", 1194, 1194, "0.0.0.0/0"), ("tcp", 22, 22, LAN)},
        "sim": {("-1", None, None, LAN), ("udp", 5000, 5010, "role:router")},
        "fc1": {("tcp", 0, 65535, "role:sim")},
        "fc2": set(),
    }


@pytest.mark.parametrize(
    ("rules", "roles", "message"),
    [
        ([FirewallRule("db", "tcp", None, "lan")], ROLES, "to_role 'db'"),
        ([FirewallRule("sim", "tcp", None, "role:db")], ROLES, "source 'role:db'"),
        ([], ["sim", "sim"], "repeat"),
        ([], ["Sim"], "^roles must be a role name"),
        (["sim tcp 22"], ROLES, "FirewallRule"),
    ],
)
def test_rules_that_do_not_fit_the_roles_are_refused_before_any_change(
    driver: CloudSimEC2NodeDriver,
    network: EC2ConstellationNetwork,
    rules: list[Any],
    roles: list[str],
    message: str,
) -> None:
    with pytest.raises(InvalidRequestError, match=message):
        driver.ex_apply_firewall(network, rules, roles)
    assert driver.ex_get_security_groups(filters={"tag:cloudsim:network": network.name}) == []
