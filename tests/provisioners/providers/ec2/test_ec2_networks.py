"""Constellation networks on moto's EC2, driven only through the driver."""

import re

import pytest

from provisioners.providers.ec2.driver import CloudSimEC2NodeDriver
from provisioners.providers.ec2.errors import (
    InvalidRequestError,
    NameInUseError,
    NetworkNotFoundError,
)
from provisioners.providers.ec2.networks import DEFAULT_CIDR

NETWORK_TAG = "cloudsim:network"


def tagged(network_name: str) -> dict[str, str]:
    return {f"tag:{NETWORK_TAG}": network_name}


def test_network_is_a_tagged_vpc_subnet_gateway_and_default_route(
    driver: CloudSimEC2NodeDriver, network_name: str
) -> None:
    network = driver.ex_create_network(network_name, "10.0.0.0/24")

    assert (network.name, network.cidr, network.gateway) == (
        network_name,
        "10.0.0.0/24",
        "10.0.0.1",
    )
    [vpc] = driver.ex_list_vpcs(filters=tagged(network_name))
    assert vpc.id == network.id
    assert vpc.cidr_block == "10.0.0.0/24"
    assert vpc.extra["tags"][NETWORK_TAG] == network_name
    [subnet] = driver.ex_list_subnets(filters=tagged(network_name))
    assert subnet.id == network.extra["subnet_id"]
    assert subnet.extra["vpc_id"] == network.id
    assert subnet.extra["cidr_block"] == "10.0.0.0/24"
    assert subnet.extra["tags"][NETWORK_TAG] == network_name
    [gateway] = driver.ex_list_internet_gateways(filters=tagged(network_name))
    assert gateway.id == network.extra["internet_gateway_id"]
    assert gateway.vpc_id == network.id
    assert gateway.extra["tags"][NETWORK_TAG] == network_name
    [route_table] = driver.ex_list_route_tables(route_table_ids=[network.extra["route_table_id"]])
    routes = {route.cidr: route.gateway_id for route in route_table.routes}
    assert routes["0.0.0.0/0"] == gateway.id

    driver.ex_destroy_network(network)


def test_creating_a_network_again_returns_it_without_duplicating_anything(
    driver: CloudSimEC2NodeDriver, network_name: str
) -> None:
    first = driver.ex_create_network(network_name, "10.1.0.0/24")
    again = driver.ex_create_network(network_name, "10.1.0.0/24")
    without_cidr = driver.ex_create_network(network_name)

    assert again == first
    assert without_cidr == first
    assert len(driver.ex_list_vpcs(filters=tagged(network_name))) == 1
    assert len(driver.ex_list_subnets(filters=tagged(network_name))) == 1
    assert len(driver.ex_list_internet_gateways(filters=tagged(network_name))) == 1
    assert driver.ex_get_network(network_name) == first
    assert first in driver.ex_list_networks()

    driver.ex_destroy_network(first)


def test_half_made_network_is_completed_on_the_next_create(
    driver: CloudSimEC2NodeDriver, network_name: str
) -> None:
    network = driver.ex_create_network(network_name)
    [gateway] = driver.ex_list_internet_gateways(filters=tagged(network_name))
    driver.ex_detach_internet_gateway(gateway, network)
    driver.ex_delete_internet_gateway(gateway)

    completed = driver.ex_create_network(network_name)

    [new_gateway] = driver.ex_list_internet_gateways(filters=tagged(network_name))
    assert new_gateway.id != gateway.id
    assert new_gateway.vpc_id == network.id
    assert completed.extra["internet_gateway_id"] == new_gateway.id
    assert completed.id == network.id
    driver.ex_destroy_network(completed)


def test_default_cidr_is_used_when_none_is_given(
    driver: CloudSimEC2NodeDriver, network_name: str
) -> None:
    network = driver.ex_create_network(network_name)
    assert network.cidr == DEFAULT_CIDR
    driver.ex_destroy_network(network)


def test_same_name_with_another_cidr_is_refused(
    driver: CloudSimEC2NodeDriver, network_name: str
) -> None:
    network = driver.ex_create_network(network_name, "10.2.0.0/24")
    with pytest.raises(NameInUseError, match=re.escape("10.2.0.0/24")):
        driver.ex_create_network(network_name, "10.3.0.0/24")
    driver.ex_destroy_network(network)


@pytest.mark.parametrize(
    ("name", "cidr", "message"),
    [
        ("Bad_Name", None, "network name"),
        ("ok", "10.0.0.0/8", "prefix length"),
        ("ok", "10.0.0.1/24", "IPv4 network"),
        ("ok", "fd00::/64", "IPv4 network"),
    ],
)
def test_bad_name_or_cidr_is_refused_before_any_change(
    driver: CloudSimEC2NodeDriver, name: str, cidr: str | None, message: str
) -> None:
    before = len(driver.ex_list_vpcs())
    with pytest.raises(InvalidRequestError, match=message):
        driver.ex_create_network(name, cidr)
    assert len(driver.ex_list_vpcs()) == before


def test_destroying_removes_everything_and_is_idempotent(
    driver: CloudSimEC2NodeDriver, network_name: str
) -> None:
    network = driver.ex_create_network(network_name)
    driver.ex_apply_firewall(network, [], ["sim"])

    assert driver.ex_destroy_network(network) is True
    assert driver.ex_destroy_network(network) is True

    assert driver.ex_list_vpcs(filters=tagged(network_name)) == []
    assert driver.ex_list_subnets(filters=tagged(network_name)) == []
    assert driver.ex_list_internet_gateways(filters=tagged(network_name)) == []
    assert driver.ex_get_security_groups(filters=tagged(network_name)) == []
    assert network_name not in [listed.name for listed in driver.ex_list_networks()]
    with pytest.raises(NetworkNotFoundError, match=network_name):
        driver.ex_get_network(network_name)
