"""The driver as libcloud sees it: registration, libcloud's own calls on moto, clean errors."""

import socket
from collections.abc import Callable, Iterator
from typing import Any

import pytest
import requests
from libcloud.compute.base import NodeAuthSSHKey, NodeImage, NodeSize
from libcloud.compute.providers import get_driver

from provisioners.providers.ec2.driver import CloudSimEC2NodeDriver
from provisioners.providers.ec2.errors import (
    EC2APIError,
    EC2ConnectionError,
    EC2CredentialsError,
    EC2ProviderError,
    InvalidRequestError,
)
from provisioners.providers.registry import PROVIDERS, register_drivers
from tests.provisioners.providers.ec2.conftest import ACCESS_KEY_ID, SECRET_ACCESS_KEY, MotoEndpoint

DriverFactory = Callable[..., CloudSimEC2NodeDriver]


def test_register_makes_the_driver_available_by_name_and_is_repeatable() -> None:
    register_drivers()
    register_drivers()
    assert get_driver(PROVIDERS["ec2"].libcloud_name) is CloudSimEC2NodeDriver


def test_libcloud_tag_and_boolean_calls_work_on_moto(
    driver: CloudSimEC2NodeDriver,
    network_name: str,
    size: NodeSize,
    image: NodeImage,
    public_key: str,
) -> None:
    network = driver.ex_create_network(network_name)
    node = driver.create_node(
        "tagged", size, image, auth=NodeAuthSSHKey(public_key), ex_network=network
    )
    try:
        assert driver.ex_create_tags(node, {"owner": "ci", "purpose": "test"}) is True
        assert driver.ex_describe_tags(node)["owner"] == "ci"
        assert driver.ex_delete_tags(node, {"owner": "ci"}) is True
        tags = driver.ex_describe_tags(node)
        assert "owner" not in tags
        assert tags["purpose"] == "test"
        assert driver.reboot_node(node) is True
    finally:
        driver.destroy_node(node)
        driver.ex_destroy_network(network)


@pytest.mark.parametrize(("key", "secret"), [("", SECRET_ACCESS_KEY), (ACCESS_KEY_ID, None)])
def test_missing_credentials_are_refused_at_construction(key: str, secret: str | None) -> None:
    with pytest.raises(EC2CredentialsError, match="access key id and a secret access key"):
        CloudSimEC2NodeDriver(key, secret)


def test_unknown_region_is_refused(make_driver: DriverFactory) -> None:
    with pytest.raises(InvalidRequestError, match="mars-north-1"):
        make_driver(region="mars-north-1")


@pytest.fixture
def credentials_checked(moto_endpoint: MotoEndpoint) -> Iterator[None]:
    """Make moto check credentials (it accepts anything by default) for one test."""
    _set_moto_auth_free_actions(moto_endpoint, "0")
    yield
    _set_moto_auth_free_actions(moto_endpoint, "inf")


def _set_moto_auth_free_actions(endpoint: MotoEndpoint, count: str) -> None:
    # moto's own control API: how many more requests it lets through without checking.
    response = requests.post(
        f"{endpoint.url}/moto-api/reset-auth",
        data=count,
        headers={"Content-Type": "text/plain"},
        timeout=10,
    )
    response.raise_for_status()


@pytest.mark.usefixtures("credentials_checked")
def test_rejected_credentials_become_a_credentials_error_without_them(
    make_driver: DriverFactory,
) -> None:
    secret = "wrong-secret-never-shown-4242"
    rejected = make_driver(key="AKIDUNKNOWN000", secret=secret)

    with pytest.raises(EC2CredentialsError) as raised:
        rejected.list_nodes()

    error = raised.value
    assert error.code == "AuthFailure"
    assert error.status == 401
    assert "credentials" in error.message
    for shown in (str(error), repr(error), error.message):
        assert secret not in shown
        assert "AKIDUNKNOWN000" not in shown


def test_aws_error_carries_aws_code_and_message(driver: CloudSimEC2NodeDriver) -> None:
    with pytest.raises(EC2APIError) as raised:
        driver.list_images(ex_image_ids=["ami-00000000000000000"])

    error = raised.value
    assert isinstance(error, EC2ProviderError)
    assert not isinstance(error, EC2CredentialsError)
    assert error.code == "InvalidAMIID.NotFound"
    assert "ami-00000000000000000" in error.message
    assert str(error).startswith("EC2 error InvalidAMIID.NotFound: ")
    assert SECRET_ACCESS_KEY not in str(error)


def test_unreachable_endpoint_becomes_a_connection_error_without_credentials(
    make_driver: DriverFactory,
) -> None:
    with socket.socket() as placeholder:  # a port that nothing listens on once closed
        placeholder.bind(("127.0.0.1", 0))
        port = placeholder.getsockname()[1]
    unreachable = make_driver(port=port)

    with pytest.raises(EC2ConnectionError, match=f"cannot reach EC2 at 127.0.0.1:{port}") as raised:
        unreachable.list_nodes()

    assert raised.value.__suppress_context__
    assert SECRET_ACCESS_KEY not in str(raised.value)
    assert ACCESS_KEY_ID not in str(raised.value)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"ex_network": None}, "ex_network"),
        ({"auth": None}, "NodeAuthSSHKey"),
        ({"auth": NodeAuthSSHKey("not a key")}, "OpenSSH public key"),
        ({"auth": NodeAuthSSHKey("ssh-ed25519 !!!notbase64")}, "base64"),
        ({"ex_tags": {"Name": "other"}}, "ex_tags\\['Name'\\]"),
        ({"ex_tags": {"cloudsim:role": 7}}, "str to str"),
        ({"size": None}, "size and an image"),
        ({"name": ""}, "^name"),
        ({"name": "sim*"}, "^name"),
        ({"ex_role": "Bad Role"}, "^ex_role must be a role name"),
        ({"ex_role": "sim", "ex_tags": {"cloudsim:role": "fc1"}}, "cloudsim:role"),
    ],
)
def test_bad_create_node_arguments_are_refused_before_launch(
    driver: CloudSimEC2NodeDriver,
    network_name: str,
    size: NodeSize,
    image: NodeImage,
    public_key: str,
    change: dict[str, Any],
    message: str,
) -> None:
    network = driver.ex_create_network(network_name)
    arguments: dict[str, Any] = {
        "name": "machine",
        "size": size,
        "image": image,
        "auth": NodeAuthSSHKey(public_key),
        "ex_network": network,
        **change,
    }
    try:
        with pytest.raises(InvalidRequestError, match=message):
            driver.create_node(**arguments)
        assert driver.ex_list_nodes_by_tags({"cloudsim:network": network_name}) == []
    finally:
        driver.ex_destroy_network(network)
