"""Fixtures for the EC2 provider: one in-process moto EC2 server per session, drivers on it."""

import itertools
import re
from collections.abc import Callable
from typing import Any

import pytest
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey
from libcloud.compute.base import NodeImage, NodeSize

from provisioners.providers.ec2.driver import CloudSimEC2NodeDriver
from tests.support.servers import MotoEndpoint

ACCESS_KEY_ID = "AKIDCLOUDSIMTEST"
SECRET_ACCESS_KEY = "cloudsim-test-secret-0123456789"
SIZE_ID = "t3.micro"
_names = itertools.count(1)


@pytest.fixture
def make_driver(moto_endpoint: MotoEndpoint) -> Callable[..., CloudSimEC2NodeDriver]:
    """Build drivers pointed at moto; credentials default to the test pair."""

    def build(
        key: str = ACCESS_KEY_ID, secret: str = SECRET_ACCESS_KEY, **kwargs: Any
    ) -> CloudSimEC2NodeDriver:
        options: dict[str, Any] = {
            "host": moto_endpoint.host,
            "port": moto_endpoint.port,
            "secure": False,
            **kwargs,
        }
        return CloudSimEC2NodeDriver(key, secret, **options)

    return build


@pytest.fixture
def driver(make_driver: Callable[..., CloudSimEC2NodeDriver]) -> CloudSimEC2NodeDriver:
    return make_driver()


@pytest.fixture
def network_name(request: pytest.FixtureRequest) -> str:
    """Return a network name no other test uses (the moto server lives for the session)."""
    label = re.sub(r"[^a-z0-9]+", "-", request.node.name.lower())[:24].strip("-")
    return f"t{next(_names)}-{label}"


@pytest.fixture(scope="session")
def public_key() -> str:
    key = Ed25519PrivateKey.generate().public_key()
    encoded = key.public_bytes(serialization.Encoding.OpenSSH, serialization.PublicFormat.OpenSSH)
    return encoded.decode() + " cloudsim-test"


@pytest.fixture(scope="session")
def catalog(moto_endpoint: MotoEndpoint) -> tuple[NodeSize, NodeImage]:
    """Return a size and an image from moto's catalogue (listing images takes a second)."""
    lister = CloudSimEC2NodeDriver(
        ACCESS_KEY_ID,
        SECRET_ACCESS_KEY,
        host=moto_endpoint.host,
        port=moto_endpoint.port,
        secure=False,
    )
    size = next(size for size in lister.list_sizes() if size.id == SIZE_ID)
    images: list[NodeImage] = lister.list_images(ex_owner="amazon")
    return size, images[0]


@pytest.fixture
def size(catalog: tuple[NodeSize, NodeImage]) -> NodeSize:
    return catalog[0]


@pytest.fixture
def image(catalog: tuple[NodeSize, NodeImage]) -> NodeImage:
    return catalog[1]
