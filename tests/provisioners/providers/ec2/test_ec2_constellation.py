"""A vrc-like constellation on moto's EC2: launched, launched again, terminated to nothing."""

from collections.abc import Iterator

import pytest
from libcloud.compute.base import Node, NodeAuthSSHKey, NodeImage, NodeSize
from libcloud.compute.types import NodeState

from provisioners.providers.ec2.driver import CloudSimEC2NodeDriver
from provisioners.providers.ec2.errors import InvalidRequestError, NameInUseError, NetworkInUseError
from provisioners.providers.ec2.networks import EC2ConstellationNetwork
from provisioners.remote.firewall import FirewallRule
from tests.provisioners.providers.ec2.test_ec2_firewall import ROLES, VRC_RULES

LAN = "10.0.0.0/24"
# name -> (private address, public?)
MACHINES = {
    "router": ("10.0.0.50", True),
    "sim": ("10.0.0.51", False),
    "fc1": ("10.0.0.52", False),
    "fc2": ("10.0.0.53", False),
}


class Constellation:
    """What a test needs to launch machines of one constellation."""

    def __init__(
        self,
        driver: CloudSimEC2NodeDriver,
        network: EC2ConstellationNetwork,
        group_ids: dict[str, str],
        size: NodeSize,
        image: NodeImage,
        public_key: str,
    ) -> None:
        self.driver = driver
        self.network = network
        self.group_ids = group_ids
        self.size = size
        self.image = image
        self.public_key = public_key
        self.name = network.name

    def launch(self, machine: str, private_ip: str | None = None, public: bool = False) -> Node:
        node: Node = self.driver.create_node(
            machine,
            self.size,
            self.image,
            auth=NodeAuthSSHKey(self.public_key),
            ex_network=self.network,
            ex_private_ip=private_ip,
            ex_public=public,
            ex_tags={"cloudsim:constellation": self.name, "cloudsim:role": machine},
            ex_role=machine,
        )
        return node

    def live_nodes(self) -> list[Node]:
        nodes: list[Node] = self.driver.ex_list_nodes_by_tags({"cloudsim:constellation": self.name})
        return nodes


@pytest.fixture
def constellation(
    driver: CloudSimEC2NodeDriver,
    network_name: str,
    size: NodeSize,
    image: NodeImage,
    public_key: str,
) -> Iterator[Constellation]:
    network = driver.ex_create_network(network_name, LAN)
    group_ids = driver.ex_apply_firewall(network, VRC_RULES, ROLES)
    made = Constellation(driver, network, group_ids, size, image, public_key)
    yield made
    for node in made.live_nodes():
        driver.destroy_node(node)
    driver.ex_destroy_network(network)


def groups_of(driver: CloudSimEC2NodeDriver, node: Node) -> set[str]:
    """Return the security group ids on the node and on its network interfaces."""
    groups = {group["group_id"] for group in node.extra["groups"]}
    for interface in driver.ex_list_network_interfaces():
        if interface.extra["attachment"].get("instance_id") == node.id:
            groups.update(group["group_id"] for group in interface.extra["groups"])
    return groups


def test_vrc_constellation_gets_its_addresses_tags_groups_and_one_public_ip(
    constellation: Constellation,
) -> None:
    launched = {
        name: constellation.launch(name, private_ip, public)
        for name, (private_ip, public) in MACHINES.items()
    }

    driver = constellation.driver
    listed = {node.name: node for node in constellation.live_nodes()}
    assert sorted(listed) == sorted(MACHINES)
    for name, (private_ip, public) in MACHINES.items():
        node = listed[name]
        assert node.id == launched[name].id
        assert node.state in (NodeState.PENDING, NodeState.RUNNING)
        assert node.private_ips == [private_ip]
        assert bool(node.public_ips) is public, (name, node.public_ips)
        assert node.extra["subnet_id"] == constellation.network.subnet_id
        assert node.extra["vpc_id"] == constellation.network.id
        assert node.extra["key_name"].startswith("cloudsim-")
        assert groups_of(driver, node) == {constellation.group_ids[name]}
        tags = node.extra["tags"]
        assert tags["Name"] == name
        assert tags["cloudsim:constellation"] == constellation.name
        assert tags["cloudsim:role"] == name
    key_names = {node.extra["key_name"] for node in listed.values()}
    assert len(key_names) == 1
    assert len([k for k in driver.list_key_pairs() if k.name in key_names]) == 1


def test_launching_a_machine_again_returns_the_same_instance(
    constellation: Constellation,
) -> None:
    first = constellation.launch("sim", "10.0.0.51")
    again = constellation.launch("sim", "10.0.0.51")
    without_address = constellation.launch("sim")

    assert again.id == first.id
    assert without_address.id == first.id
    assert [node.id for node in constellation.live_nodes()] == [first.id]


def test_a_live_machine_with_other_settings_is_not_taken_for_the_requested_one(
    constellation: Constellation,
) -> None:
    constellation.launch("sim", "10.0.0.51")
    with pytest.raises(NameInUseError, match="other settings"):
        constellation.launch("sim", "10.0.0.60")
    assert len(constellation.live_nodes()) == 1


def test_a_terminated_machine_is_replaced_by_a_new_one(constellation: Constellation) -> None:
    first = constellation.launch("fc1", "10.0.0.52")
    assert constellation.driver.destroy_node(first) is True

    second = constellation.launch("fc1", "10.0.0.52")

    assert second.id != first.id
    assert [node.id for node in constellation.live_nodes()] == [second.id]


@pytest.mark.parametrize(
    ("private_ip", "message"),
    [
        ("10.0.1.5", "not usable"),
        ("10.0.0.2", "not usable"),
        ("10.0.0.255", "not usable"),
        ("10.0.0.x", "IPv4 address"),
    ],
)
def test_unusable_private_address_is_refused_before_launch(
    constellation: Constellation, private_ip: str, message: str
) -> None:
    with pytest.raises(InvalidRequestError, match=message):
        constellation.launch("sim", private_ip)
    assert constellation.live_nodes() == []


def test_machine_launched_before_the_firewall_starts_closed_and_gets_the_rules_later(
    driver: CloudSimEC2NodeDriver,
    network_name: str,
    size: NodeSize,
    image: NodeImage,
    public_key: str,
) -> None:
    network = driver.ex_create_network(network_name, LAN)
    # The engine's way: the role only in ex_tags, the firewall applied after the launch.
    node = driver.create_node(
        name=f"{network_name}-sim",
        size=size,
        image=image,
        auth=NodeAuthSSHKey(public_key),
        ex_network=network,
        ex_private_ip="10.0.0.51",
        ex_tags={"cloudsim:constellation": network_name, "cloudsim:role": "sim"},
    )
    try:
        [group] = driver.ex_get_security_groups(filters={"group-name": f"{network_name}-sim"})
        assert group.ingress_rules == []
        assert groups_of(driver, node) == {group.id}

        group_ids = driver.ex_apply_firewall(network, VRC_RULES, ROLES)

        assert group_ids["sim"] == group.id
        [applied] = driver.ex_get_security_groups(group_ids=[group.id])
        assert [rule["cidr_ips"] for rule in applied.ingress_rules] == [[LAN]]
    finally:
        driver.destroy_node(node)
        driver.ex_destroy_network(network)


def test_terminating_everything_leaves_nothing_behind(
    driver: CloudSimEC2NodeDriver, constellation: Constellation
) -> None:
    network = constellation.network
    for name, (private_ip, public) in MACHINES.items():
        constellation.launch(name, private_ip, public)
    with pytest.raises(NetworkInUseError, match="destroy them first"):
        driver.ex_destroy_network(network)

    nodes = constellation.live_nodes()
    assert all(driver.destroy_node(node) for node in nodes)
    assert all(driver.destroy_node(node) for node in nodes)  # already terminated
    assert driver.ex_destroy_network(network) is True

    assert constellation.live_nodes() == []
    all_states = driver.ex_list_nodes_by_tags(
        {"cloudsim:constellation": constellation.name}, ex_include_terminated=True
    )
    assert sorted(node.name for node in all_states) == sorted(MACHINES)
    assert {node.state for node in all_states} == {NodeState.TERMINATED}
    tagged = {"tag:cloudsim:network": network.name}
    assert driver.ex_list_vpcs(filters={"vpc-id": network.id}) == []
    assert driver.ex_list_subnets(filters={"subnet-id": network.subnet_id}) == []
    assert driver.ex_list_subnets(filters=tagged) == []
    assert driver.ex_get_security_groups(filters={"vpc-id": network.id}) == []
    assert driver.ex_get_security_groups(filters=tagged) == []
    assert driver.ex_list_internet_gateways(filters=tagged) == []
    assert network.name not in [listed.name for listed in driver.ex_list_networks()]


def test_unused_rule_roles_do_not_stop_a_machine_of_another_role(
    constellation: Constellation,
) -> None:
    extra = [*VRC_RULES, FirewallRule("sim", "tcp", (8080, 8080), "role:router")]
    group_ids = constellation.driver.ex_apply_firewall(constellation.network, extra, ROLES)
    router = constellation.launch("router", "10.0.0.50", public=True)
    assert groups_of(constellation.driver, router) == {group_ids["router"]}


def test_listing_by_tags_matches_values_exactly_not_as_patterns(
    constellation: Constellation,
) -> None:
    sim = constellation.launch("sim", "10.0.0.51")
    driver = constellation.driver

    exact = driver.ex_list_nodes_by_tags({"cloudsim:constellation": constellation.name})
    pattern = driver.ex_list_nodes_by_tags({"cloudsim:constellation": constellation.name[:3] + "*"})

    assert [node.id for node in exact] == [sim.id]
    assert pattern == []
