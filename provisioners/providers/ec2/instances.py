"""Instance requests: tags, addresses and the RunInstances parameters of one machine."""

import ipaddress
import re
from collections.abc import Mapping
from dataclasses import dataclass

from provisioners.providers.ec2.api import (
    CONSTELLATION_TAG,
    NAME_TAG,
    NETWORK_TAG,
    ROLE_TAG,
    tag_specification,
)
from provisioners.providers.ec2.errors import InvalidRequestError
from provisioners.providers.ec2.networks import EC2ConstellationNetwork

NOT_TERMINATED_STATES = ["pending", "running", "stopping", "stopped"]
# AWS keeps the first four addresses and the last one of every subnet.
_RESERVED_AT_START = 4
_NODE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,62}\Z")


@dataclass(frozen=True)
class InstanceRequest:
    """Everything RunInstances needs to launch one machine of a constellation."""

    name: str
    image_id: str
    size_id: str
    key_name: str
    subnet_id: str
    private_ip: str | None
    public: bool
    security_group_id: str | None
    tags: dict[str, str]

    def params(self) -> dict[str, str]:
        """Return the RunInstances parameters for this request."""
        params = {
            "ImageId": self.image_id,
            "InstanceType": self.size_id,
            "MinCount": "1",
            "MaxCount": "1",
            "KeyName": self.key_name,
            **tag_specification("instance", self.tags),
        }
        # One explicit primary interface: the only way to ask for (or refuse) a public address,
        # and it spells out DeleteOnTermination (moto otherwise keeps the address in use).
        root = "NetworkInterface.1"
        params[f"{root}.DeviceIndex"] = "0"
        params[f"{root}.SubnetId"] = self.subnet_id
        params[f"{root}.AssociatePublicIpAddress"] = "true" if self.public else "false"
        params[f"{root}.DeleteOnTermination"] = "true"
        if self.private_ip is not None:
            params[f"{root}.PrivateIpAddress"] = self.private_ip
        if self.security_group_id is not None:
            params[f"{root}.SecurityGroupId.1"] = self.security_group_id
        return params


def check_node_name(name: object) -> str:
    """Return name if it is a valid machine name, else raise InvalidRequestError."""
    if not isinstance(name, str) or not _NODE_NAME.match(name):
        raise InvalidRequestError(
            "name must be 1-63 letters, digits, '.', '_' or '-', starting with a letter or "
            f"digit, got {name!r}"
        )
    return name


def instance_tags(
    name: str,
    network: EC2ConstellationNetwork,
    tags: Mapping[str, str] | None,
    role: str | None,
) -> dict[str, str]:
    """Return the instance's tags: the caller's plus Name, network, constellation and role."""
    merged = dict(tags or {})
    for key, value in merged.items():
        if not isinstance(key, str) or not isinstance(value, str):
            raise InvalidRequestError(f"ex_tags must map str to str (got {key!r}: {value!r})")
    required = {NAME_TAG: name, NETWORK_TAG: network.name}
    if role is not None:
        required[ROLE_TAG] = role
    for key, value in required.items():
        if merged.get(key, value) != value:
            raise InvalidRequestError(f"ex_tags[{key!r}] is {merged[key]!r}, not {value!r}")
        merged[key] = value
    merged.setdefault(CONSTELLATION_TAG, network.name)
    return merged


def check_private_ip(private_ip: str | None, network: EC2ConstellationNetwork) -> str | None:
    """Return private_ip if EC2 can give it to a machine in network's subnet, else raise."""
    if private_ip is None:
        return None
    try:
        address = ipaddress.IPv4Address(private_ip)
    except ValueError:
        raise InvalidRequestError(
            f"ex_private_ip must be an IPv4 address, got {private_ip!r}"
        ) from None
    subnet = ipaddress.IPv4Network(network.cidr)
    usable_first = subnet.network_address + _RESERVED_AT_START
    if not usable_first <= address < subnet.broadcast_address:
        raise InvalidRequestError(
            f"ex_private_ip {address} is not usable in {subnet} (AWS reserves the first four "
            "addresses and the last)"
        )
    return str(address)
