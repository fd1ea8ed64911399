"""Subnet pool and host address allocation, name checks: pure functions, no root needed."""

import re
from ipaddress import IPv4Address, IPv4Network

import pytest

from provisioners.providers.local.addresses import (
    allocate_address,
    allocate_subnet,
    check_address_free,
    check_name,
    check_prefix,
    check_subnet_free,
    count_free_subnets,
    gateway_address,
    interface_cidr,
    parse_address,
    parse_subnet,
)
from provisioners.providers.local.errors import (
    AddressError,
    InvalidRequestError,
    LocalProviderError,
)

POOL = IPv4Network("10.211.0.0/16")


def test_first_subnet_of_an_empty_pool_is_its_first_24() -> None:
    assert allocate_subnet(POOL, []) == IPv4Network("10.211.0.0/24")


def test_allocation_skips_every_taken_or_overlapping_subnet() -> None:
    taken = [
        IPv4Network("10.211.0.0/24"),
        IPv4Network("10.211.1.128/25"),  # overlaps 10.211.1.0/24 partly
        IPv4Network("10.211.2.0/23"),  # covers .2 and .3
    ]
    assert allocate_subnet(POOL, taken) == IPv4Network("10.211.4.0/24")


def test_a_freed_subnet_is_reused() -> None:
    taken = [IPv4Network("10.211.0.0/24"), IPv4Network("10.211.2.0/24")]
    assert allocate_subnet(POOL, taken) == IPv4Network("10.211.1.0/24")


def test_subnets_outside_the_pool_do_not_matter() -> None:
    assert allocate_subnet(POOL, [IPv4Network("10.0.0.0/24")]) == IPv4Network("10.211.0.0/24")


def test_exhausted_pool_is_an_address_error() -> None:
    pool = IPv4Network("10.211.0.0/23")
    taken = list(pool.subnets(new_prefix=24))
    with pytest.raises(
        AddressError, match=re.escape("no free /24 left in the subnet pool 10.211.0.0/23")
    ):
        allocate_subnet(pool, taken)


def test_pool_smaller_than_one_subnet_is_refused() -> None:
    with pytest.raises(AddressError, match="smaller than one /24"):
        allocate_subnet(IPv4Network("10.211.0.0/25"), [])


def test_sequential_allocations_never_repeat() -> None:
    taken: list[IPv4Network] = []
    for _ in range(20):
        taken.append(allocate_subnet(POOL, taken))
    assert len(set(taken)) == 20
    assert all(subnet.subnet_of(POOL) for subnet in taken)


def test_explicit_subnet_overlapping_one_in_use_is_refused() -> None:
    with pytest.raises(AddressError, match=re.escape("overlaps 10.211.0.0/16")):
        check_subnet_free(IPv4Network("10.211.5.0/24"), [POOL])
    check_subnet_free(IPv4Network("10.212.0.0/24"), [POOL])


def test_host_addresses_skip_the_gateway_and_taken_ones() -> None:
    subnet = IPv4Network("10.211.7.0/24")
    assert gateway_address(subnet) == IPv4Address("10.211.7.1")
    assert allocate_address(subnet, []) == IPv4Address("10.211.7.2")
    taken = [IPv4Address("10.211.7.2"), IPv4Address("10.211.7.4")]
    assert allocate_address(subnet, taken) == IPv4Address("10.211.7.3")


def test_full_subnet_is_an_address_error() -> None:
    subnet = IPv4Network("10.211.7.0/29")
    with pytest.raises(AddressError, match=re.escape("no free address left in 10.211.7.0/29")):
        allocate_address(subnet, list(subnet.hosts()))


@pytest.mark.parametrize(
    ("address", "message"),
    [
        ("10.211.8.0", "not a host address"),
        ("10.211.8.255", "not a host address"),
        ("10.211.9.5", "not a host address"),
        ("10.211.8.50", "already used"),
    ],
)
def test_requested_address_must_be_a_free_host_address(address: str, message: str) -> None:
    subnet = IPv4Network("10.211.8.0/24")
    with pytest.raises(AddressError, match=message):
        check_address_free(subnet, IPv4Address(address), [IPv4Address("10.211.8.50")])


def test_requested_gateway_address_is_allowed_when_free() -> None:
    subnet = IPv4Network("10.211.8.0/24")
    check_address_free(subnet, IPv4Address("10.211.8.1"), [])


@pytest.mark.parametrize("text", ["10.211.0.1/24", "fd00::/64", "nonsense", "10.0.0.0/30"])
def test_bad_subnets_are_invalid_requests(text: str) -> None:
    with pytest.raises(InvalidRequestError):
        parse_subnet(text)


@pytest.mark.parametrize("text", ["10.211.0.256", "::1", ""])
def test_bad_addresses_are_invalid_requests(text: str) -> None:
    with pytest.raises(InvalidRequestError):
        parse_address(text)


def test_interface_cidr_joins_address_and_prefix_length() -> None:
    assert interface_cidr(IPv4Address("10.211.3.9"), IPv4Network("10.211.3.0/24")) == (
        "10.211.3.9/24"
    )


@pytest.mark.parametrize("name", ["router", "fc-1", "a", "vrc7-sim"])
def test_hostname_like_names_are_accepted(name: str) -> None:
    assert check_name("node", name) == name


@pytest.mark.parametrize("name", ["", "-x", "x-", "Router", "a_b", "a.b", "x" * 41, "a/b"])
def test_other_names_are_refused(name: str) -> None:
    with pytest.raises(InvalidRequestError, match="invalid node name"):
        check_name("node", name)


@pytest.mark.parametrize(
    ("prefix", "valid"), [("cs", True), ("cst123", True), ("1cs", False), ("c-s", False)]
)
def test_prefixes_are_short_words(prefix: str, valid: bool) -> None:
    if valid:
        assert check_prefix(prefix) == prefix
    else:
        with pytest.raises(LocalProviderError, match="invalid prefix"):
            check_prefix(prefix)


def test_free_subnets_are_counted_as_testing_each_candidate_would() -> None:
    pool = IPv4Network("10.211.0.0/20")
    cases = [
        [],
        [IPv4Network("10.211.3.0/24")],
        [IPv4Network("10.211.3.0/28"), IPv4Network("10.211.3.64/26")],  # one /24 twice
        [IPv4Network("10.211.4.0/22"), IPv4Network("10.211.5.0/24")],  # a bigger one
        [IPv4Network("10.210.0.0/15")],  # the whole pool and beyond
        [IPv4Network("10.211.15.0/24"), IPv4Network("10.212.0.0/24")],  # last one, outside
    ]
    for taken in cases:
        candidates = pool.subnets(new_prefix=24)
        expected = sum(1 for c in candidates if not any(c.overlaps(t) for t in taken))
        assert count_free_subnets(pool, 24, taken) == expected, taken
