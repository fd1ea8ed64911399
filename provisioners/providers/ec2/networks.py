"""Constellation networks on EC2: a VPC, one subnet, an internet gateway and a default route."""

import ipaddress
import re
import time
from xml.etree.ElementTree import Element

from provisioners.providers.base import ProviderNetwork
from provisioners.providers.ec2.api import (
    NETWORK_TAG,
    EC2Api,
    items,
    required_child,
    required_text,
    resource_tags,
    tag_specification,
    text,
)
from provisioners.providers.ec2.errors import (
    EC2TimeoutError,
    InvalidRequestError,
    NameInUseError,
    NetworkInUseError,
    NetworkNotFoundError,
)
from provisioners.providers.ec2.permissions import permission_params, read_permissions

DEFAULT_CIDR = "10.0.0.0/24"
INTERNET_CIDR = "0.0.0.0/0"
# AWS's limits on a VPC's (and so on our one subnet's) IPv4 block.
MIN_PREFIXLEN = 16
MAX_PREFIXLEN = 28
LIVE_INSTANCE_STATES = ["pending", "running", "stopping", "stopped"]
DYING_INSTANCE_STATES = ["shutting-down"]
POLL_SECONDS = 2.0

# Network names become tags and security group name prefixes ("<network>-<role>").
_NETWORK_NAME = re.compile(r"[a-z0-9][a-z0-9-]{0,62}\Z")


class EC2ConstellationNetwork(ProviderNetwork):
    """A constellation's network on EC2, as handed to create_node(ex_network=...).

    id is the VPC id, cidr the subnet's (and VPC's) block, gateway the VPC router's address.
    """

    @property
    def subnet_id(self) -> str:
        """Return the id of the subnet machines are launched into."""
        return str(self.extra["subnet_id"])


def check_network_name(name: object) -> str:
    """Return name if it is a valid network name, else raise InvalidRequestError."""
    if not isinstance(name, str) or not _NETWORK_NAME.match(name):
        raise InvalidRequestError(
            "network name must be 1-63 lowercase letters, digits or '-', starting with a "
            f"letter or digit, got {name!r}"
        )
    return name


def parse_cidr(cidr: str) -> ipaddress.IPv4Network:
    """Return cidr as a network if EC2 accepts it as a VPC block, else raise InvalidRequestError."""
    try:
        network = ipaddress.IPv4Network(cidr)
    except (ValueError, TypeError) as error:
        raise InvalidRequestError(
            f"cidr must be an IPv4 network like {DEFAULT_CIDR}: {error}"
        ) from None
    if not MIN_PREFIXLEN <= network.prefixlen <= MAX_PREFIXLEN:
        raise InvalidRequestError(
            f"cidr must have a prefix length from /{MIN_PREFIXLEN} to /{MAX_PREFIXLEN}, got {cidr}"
        )
    return network


def ensure_network(api: EC2Api, name: str, cidr: str | None, zone: str) -> EC2ConstellationNetwork:
    """Return the named network, creating whichever of its parts do not exist yet."""
    check_network_name(name)
    wanted_cidr = str(parse_cidr(cidr or DEFAULT_CIDR))
    tags = {NETWORK_TAG: name, "Name": name}
    vpc = _find_one(api, "DescribeVpcs", "vpcSet", name)
    if vpc is None:
        answer = api.call("CreateVpc", {"CidrBlock": wanted_cidr, **tag_specification("vpc", tags)})
        vpc = required_child(answer, "vpc")
    vpc_id = required_text(vpc, "vpcId")
    vpc_cidr = required_text(vpc, "cidrBlock")
    if cidr is not None and vpc_cidr != wanted_cidr:
        raise NameInUseError(f"network {name!r} exists with cidr {vpc_cidr}, not {wanted_cidr}")
    subnet = _find_one(api, "DescribeSubnets", "subnetSet", name)
    if subnet is None:
        answer = api.call(
            "CreateSubnet",
            {
                "VpcId": vpc_id,
                "CidrBlock": vpc_cidr,
                "AvailabilityZone": zone,
                **tag_specification("subnet", tags),
            },
        )
        subnet = required_child(answer, "subnet")
    gateway = _find_one(api, "DescribeInternetGateways", "internetGatewaySet", name)
    if gateway is None:
        answer = api.call("CreateInternetGateway", tag_specification("internet-gateway", tags))
        gateway = required_child(answer, "internetGateway")
    gateway_id = required_text(gateway, "internetGatewayId")
    attached_vpcs = {text(item, "vpcId") for item in items(gateway, "attachmentSet/item")}
    if vpc_id not in attached_vpcs:
        api.call("AttachInternetGateway", {"InternetGatewayId": gateway_id, "VpcId": vpc_id})
    route_table_id = _ensure_internet_route(api, vpc_id, gateway_id)
    return _to_network(api, name, vpc, subnet, gateway_id, route_table_id)


def find_network(api: EC2Api, name: str) -> EC2ConstellationNetwork | None:
    """Return the named network if its VPC and subnet exist, else None."""
    check_network_name(name)
    vpc = _find_one(api, "DescribeVpcs", "vpcSet", name)
    subnet = _find_one(api, "DescribeSubnets", "subnetSet", name)
    if vpc is None or subnet is None:
        return None
    gateway = _find_one(api, "DescribeInternetGateways", "internetGatewaySet", name)
    gateway_id = required_text(gateway, "internetGatewayId") if gateway is not None else None
    route_table = _main_route_table(api, required_text(vpc, "vpcId"))
    route_table_id = required_text(route_table, "routeTableId") if route_table else None
    return _to_network(api, name, vpc, subnet, gateway_id, route_table_id)


def list_network_names(api: EC2Api) -> list[str]:
    """Return the names of the networks whose VPC exists, sorted."""
    vpcs = api.describe("DescribeVpcs", "vpcSet", {"tag-key": NETWORK_TAG})
    return sorted({resource_tags(vpc)[NETWORK_TAG] for vpc in vpcs})


def destroy_network(api: EC2Api, name: str, timeout: float) -> None:
    """Delete the network's security groups, gateway, subnet and VPC; no-op when gone.

    Refuses while live instances are in it; waits up to timeout for dying ones to go.
    """
    check_network_name(name)
    vpc_ids = [required_text(vpc, "vpcId") for vpc in _tagged(api, "DescribeVpcs", "vpcSet", name)]
    for vpc_id in vpc_ids:
        live = _instance_ids(api, vpc_id, LIVE_INSTANCE_STATES)
        if live:
            instances = ", ".join(sorted(live))
            raise NetworkInUseError(
                f"network {name!r} still has instances {instances}: destroy them first"
            )
    for vpc_id in vpc_ids:
        _await_no_dying_instances(api, name, vpc_id, timeout)
    _delete_security_groups(api, name)
    for gateway in _tagged(api, "DescribeInternetGateways", "internetGatewaySet", name):
        gateway_id = required_text(gateway, "internetGatewayId")
        for attachment in items(gateway, "attachmentSet/item"):
            api.call_ignoring(
                ["Gateway.NotAttached", "InvalidInternetGatewayID.NotFound"],
                "DetachInternetGateway",
                {"InternetGatewayId": gateway_id, "VpcId": required_text(attachment, "vpcId")},
            )
        api.call_ignoring(
            ["InvalidInternetGatewayID.NotFound"],
            "DeleteInternetGateway",
            {"InternetGatewayId": gateway_id},
        )
    for subnet in _tagged(api, "DescribeSubnets", "subnetSet", name):
        api.call_ignoring(
            ["InvalidSubnetID.NotFound"],
            "DeleteSubnet",
            {"SubnetId": required_text(subnet, "subnetId")},
        )
    for vpc_id in vpc_ids:
        api.call_ignoring(["InvalidVpcID.NotFound"], "DeleteVpc", {"VpcId": vpc_id})


def _delete_security_groups(api: EC2Api, name: str) -> None:
    groups = _tagged(api, "DescribeSecurityGroups", "securityGroupInfo", name)
    # A group referenced by another group's rule cannot be deleted: drop those rules first.
    for group in groups:
        group_id = required_text(group, "groupId")
        for direction, action in (
            ("ipPermissions", "RevokeSecurityGroupIngress"),
            ("ipPermissionsEgress", "RevokeSecurityGroupEgress"),
        ):
            permissions = {p for p in read_permissions(group, direction) if p.group_id}
            if permissions:
                api.call_ignoring(
                    ["InvalidPermission.NotFound", "InvalidGroup.NotFound"],
                    action,
                    {"GroupId": group_id, **permission_params(permissions)},
                )
    for group in groups:
        api.call_ignoring(
            ["InvalidGroup.NotFound"],
            "DeleteSecurityGroup",
            {"GroupId": required_text(group, "groupId")},
        )


def _ensure_internet_route(api: EC2Api, vpc_id: str, gateway_id: str) -> str:
    route_table = _main_route_table(api, vpc_id)
    if route_table is None:
        raise NetworkNotFoundError(f"VPC {vpc_id} has no main route table")
    route_table_id = required_text(route_table, "routeTableId")
    targets = {
        text(route, "destinationCidrBlock"): text(route, "gatewayId")
        for route in items(route_table, "routeSet/item")
    }
    if targets.get(INTERNET_CIDR) == gateway_id:
        return route_table_id
    params = {
        "RouteTableId": route_table_id,
        "DestinationCidrBlock": INTERNET_CIDR,
        "GatewayId": gateway_id,
    }
    api.call("ReplaceRoute" if INTERNET_CIDR in targets else "CreateRoute", params)
    return route_table_id


def _main_route_table(api: EC2Api, vpc_id: str) -> Element | None:
    tables = api.describe(
        "DescribeRouteTables",
        "routeTableSet",
        {"vpc-id": vpc_id, "association.main": "true"},
    )
    return tables[0] if tables else None


def _instance_ids(api: EC2Api, vpc_id: str, states: list[str]) -> set[str]:
    reservations = api.describe(
        "DescribeInstances",
        "reservationSet",
        {"vpc-id": vpc_id, "instance-state-name": states},
    )
    return {
        required_text(instance, "instanceId")
        for reservation in reservations
        for instance in items(reservation, "instancesSet/item")
    }


def _await_no_dying_instances(api: EC2Api, name: str, vpc_id: str, timeout: float) -> None:
    # A shutting-down instance still holds its network interface, so the subnet cannot go yet.
    deadline = time.monotonic() + timeout
    while dying := _instance_ids(api, vpc_id, DYING_INSTANCE_STATES):
        if time.monotonic() >= deadline:
            raise EC2TimeoutError(
                f"network {name!r}: instances {', '.join(sorted(dying))} still shutting down "
                f"after {timeout:.0f} s"
            )
        time.sleep(POLL_SECONDS)


def _tagged(api: EC2Api, action: str, set_name: str, name: str) -> list[Element]:
    return api.describe(action, set_name, {f"tag:{NETWORK_TAG}": name})


def _find_one(api: EC2Api, action: str, set_name: str, name: str) -> Element | None:
    found = _tagged(api, action, set_name, name)
    if len(found) > 1:
        raise NameInUseError(f"{len(found)} results of {action} are tagged as network {name!r}")
    return found[0] if found else None


def _to_network(
    api: EC2Api,
    name: str,
    vpc: Element,
    subnet: Element,
    gateway_id: str | None,
    route_table_id: str | None,
) -> EC2ConstellationNetwork:
    cidr = ipaddress.IPv4Network(required_text(subnet, "cidrBlock"))
    return EC2ConstellationNetwork(
        id=required_text(vpc, "vpcId"),
        name=name,
        cidr=str(cidr),
        gateway=str(cidr.network_address + 1),  # AWS's VPC router
        driver=api.driver,
        extra={
            "vpc_id": required_text(vpc, "vpcId"),
            "subnet_id": required_text(subnet, "subnetId"),
            "availability_zone": text(subnet, "availabilityZone"),
            "internet_gateway_id": gateway_id,
            "route_table_id": route_table_id,
            "tags": resource_tags(vpc),
        },
    )
