"""CloudSimEC2NodeDriver: libcloud's EC2 driver with the extension methods the engine calls."""

from collections.abc import Mapping, Sequence
from typing import Any
from xml.etree.ElementTree import Element

from libcloud.compute.base import Node, NodeAuthSSHKey, NodeImage, NodeLocation, NodeSize
from libcloud.compute.drivers.ec2 import NAMESPACE, EC2NodeDriver
from libcloud.compute.types import NodeState

from provisioners.providers.base import CloudSimNodeDriver
from provisioners.providers.ec2 import keys, networks, security_groups
from provisioners.providers.ec2.api import CONSTELLATION_TAG, NAME_TAG, ROLE_TAG, EC2Api, tag_params
from provisioners.providers.ec2.connection import CloudSimEC2Connection
from provisioners.providers.ec2.errors import (
    EC2APIError,
    EC2CredentialsError,
    EC2ProviderError,
    InvalidRequestError,
    NameInUseError,
    NetworkNotFoundError,
)
from provisioners.providers.ec2.instances import (
    NOT_TERMINATED_STATES,
    InstanceRequest,
    check_node_name,
    check_private_ip,
    instance_tags,
)
from provisioners.providers.ec2.networks import EC2ConstellationNetwork
from provisioners.remote.firewall import FirewallRule

DEFAULT_DESTROY_TIMEOUT_SECONDS = 300.0
DEFAULT_REQUEST_TIMEOUT_SECONDS = 60.0
_GONE_INSTANCE_CODES = ("InvalidInstanceID.NotFound", "InvalidInstanceID.Malformed")


class CloudSimEC2NodeDriver(EC2NodeDriver, CloudSimNodeDriver):  # type: ignore[misc]
    """Amazon EC2 for CloudSim: constellation networks, firewalls and idempotent launches."""

    error_class = EC2ProviderError

    type = "cloudsim-ec2"  # type: ignore[assignment]  # libcloud expects a Provider enum
    name = "CloudSim Amazon EC2"
    connectionCls = CloudSimEC2Connection

    def __init__(
        self,
        key: str,
        secret: str | None = None,
        secure: bool = True,
        host: str | None = None,
        port: int | None = None,
        region: str = "us-east-1",
        token: str | None = None,
        # moto only verifies SigV4; AWS accepts it in every region (SigV2 is deprecated).
        signature_version: str = "4",
        ex_availability_zone: str | None = None,
        timeout: float = DEFAULT_REQUEST_TIMEOUT_SECONDS,
        **kwargs: Any,
    ) -> None:
        if not key or not secret:
            raise EC2CredentialsError(
                "MissingCredentials", "an access key id and a secret access key are required"
            )
        try:
            super().__init__(
                key,
                secret,
                secure=secure,
                host=host,
                port=port,
                region=region,
                token=token,
                signature_version=signature_version,
                timeout=timeout,  # libcloud's default is none: a silent endpoint would hang us
                **kwargs,
            )
        except ValueError as error:  # libcloud's "Invalid region"
            raise InvalidRequestError(str(error)) from None
        self._api = EC2Api(self)
        self._availability_zone = ex_availability_zone

    # -- networks ------------------------------------------------------------------------------

    def ex_create_network(  # type: ignore[override]
        self, name: str, cidr: str | None = None
    ) -> EC2ConstellationNetwork:
        """Create (or complete) the named network: VPC and subnet on cidr, gateway, route.

        cidr defaults to networks.DEFAULT_CIDR (10.0.0.0/24); the VPC and its one subnet share
        it. An existing network of that name is returned as it is (and must match cidr if given).
        """
        existing = networks.find_network(self._api, name)
        zone = existing.extra["availability_zone"] if existing else self._zone()
        return networks.ensure_network(self._api, name, cidr, zone)

    def ex_list_networks(self) -> list[EC2ConstellationNetwork]:  # type: ignore[override]
        """Return every CloudSim network in this region."""
        found = [
            networks.find_network(self._api, name)
            for name in networks.list_network_names(self._api)
        ]
        return [network for network in found if network is not None]

    def ex_list_vpcs(
        self, network_ids: list[str] | None = None, filters: dict[str, Any] | None = None
    ) -> list[Any]:
        """Return libcloud's EC2Network objects for VPCs (libcloud's own ex_list_networks)."""
        return list(super().ex_list_networks(network_ids=network_ids, filters=filters))

    def ex_get_network(self, name: str) -> EC2ConstellationNetwork:
        """Return the named network or raise NetworkNotFoundError."""
        network = networks.find_network(self._api, name)
        if network is None:
            raise NetworkNotFoundError(f"no network {name!r} in region {self.region_name}")
        return network

    def ex_destroy_network(
        self,
        network: EC2ConstellationNetwork,
        ex_timeout: float = DEFAULT_DESTROY_TIMEOUT_SECONDS,
    ) -> bool:
        """Delete the network's security groups, gateway, subnet and VPC; True if already gone.

        Raises NetworkInUseError while instances other than terminating ones are in it.
        """
        networks.destroy_network(self._api, network.name, ex_timeout)
        return True

    def ex_apply_firewall(
        self,
        network: EC2ConstellationNetwork,
        rules: Sequence[FirewallRule],
        roles: Sequence[str],
    ) -> dict[str, str]:
        """Give each role a security group allowing exactly rules' traffic; return role -> id."""
        return security_groups.apply_firewall(self._api, network, rules, roles)

    # -- nodes ---------------------------------------------------------------------------------

    def create_node(  # type: ignore[override]
        self,
        name: str,
        size: NodeSize | None = None,
        image: NodeImage | None = None,
        location: NodeLocation | None = None,
        auth: NodeAuthSSHKey | None = None,
        ex_network: EC2ConstellationNetwork | None = None,
        ex_private_ip: str | None = None,
        ex_public: bool = False,
        ex_tags: dict[str, str] | None = None,
        ex_role: str | None = None,
    ) -> Node:
        """Launch a machine into ex_network, or return the live one of that name already there.

        The role (ex_role, else ex_tags["cloudsim:role"]) picks the machine's security group,
        made empty if ex_apply_firewall has not run yet; without a role the VPC's default group
        applies. Only ex_public machines get a public address.
        """
        check_node_name(name)
        if size is None or image is None:
            raise InvalidRequestError("create_node needs a size and an image on EC2")
        if ex_network is None:
            raise InvalidRequestError("create_node needs ex_network (from ex_create_network)")
        if not isinstance(auth, NodeAuthSSHKey):
            raise InvalidRequestError("create_node needs auth=NodeAuthSSHKey(public_key)")
        zone = ex_network.extra.get("availability_zone")
        location_zone = getattr(getattr(location, "availability_zone", None), "name", zone)
        if location_zone != zone:
            raise InvalidRequestError(f"location {location_zone} is not the subnet's zone {zone}")
        tags = instance_tags(name, ex_network, ex_tags, ex_role)
        role = tags.get(ROLE_TAG)
        private_ip = check_private_ip(ex_private_ip, ex_network)
        public_key = keys.check_public_key(auth.pubkey)
        existing = self._find_live_instance(tags)
        if existing is not None:
            return self._check_existing(existing, ex_network, private_ip)
        group_id = None
        if role is not None:
            # The engine may launch before it applies the firewall: start closed, not open.
            group_id = security_groups.ensure_group_id(self._api, ex_network, role)
        request = InstanceRequest(
            name=name,
            image_id=image.id,
            size_id=size.id,
            key_name=keys.ensure_key_pair(self._api, public_key),
            subnet_id=ex_network.subnet_id,
            private_ip=private_ip,
            public=ex_public,
            security_group_id=group_id,
            tags=tags,
        )
        answer = self._api.call("RunInstances", request.params())
        node: Node = self._to_nodes(answer, "instancesSet/item")[0]
        node.name = name
        node.extra["tags"] = tags
        return node

    def ex_list_nodes_by_tags(
        self, tags: Mapping[str, str], ex_include_terminated: bool = False
    ) -> list[Node]:
        """Return the nodes carrying every one of tags (terminated ones only if asked)."""
        if not tags:
            raise InvalidRequestError("ex_list_nodes_by_tags needs at least one tag")
        filters: dict[str, str | list[str]] = {f"tag:{key}": value for key, value in tags.items()}
        if not ex_include_terminated:
            filters["instance-state-name"] = NOT_TERMINATED_STATES
        # libcloud's type comment says str; the code takes the dict its docstring describes.
        nodes: list[Node] = self.list_nodes(ex_filters=filters)  # type: ignore[arg-type]
        # EC2 filter values are wildcard patterns ("*", "?"): keep exact matches only.
        return [
            node
            for node in nodes
            if all(node.extra.get("tags", {}).get(key) == value for key, value in tags.items())
        ]

    def destroy_node(self, node: Node) -> bool:
        """Terminate the node; True also when it is already terminated or unknown to EC2."""
        # Checking first also spares moto a second termination, which it answers with an error.
        try:
            current = self.list_nodes(ex_node_ids=[str(node.id)])  # type: ignore[arg-type]
        except EC2APIError as error:
            if error.code in _GONE_INSTANCE_CODES:
                return True
            raise
        if not current or current[0].state == NodeState.TERMINATED:
            return True
        return bool(super().destroy_node(node))

    # -- moto compatibility, harmless against AWS ---------------------------------------------

    def ex_create_tags(self, resource: Any, tags: dict[str, str]) -> bool:
        """Add tags to resource (numbered from 1: moto rejects libcloud's 0-based lists)."""
        if not tags:
            return True
        params = {"ResourceId.1": resource.id, **tag_params(tags)}
        return self._get_boolean(self._api.call("CreateTags", params))

    def ex_delete_tags(self, resource: Any, tags: dict[str, str | None]) -> bool:
        """Remove tags from resource (numbered from 1: moto rejects libcloud's 0-based lists)."""
        if not tags:
            return True
        params = {"ResourceId.1": resource.id, **tag_params(tags)}
        return self._get_boolean(self._api.call("DeleteTags", params))

    def _get_boolean(self, element: Element) -> bool:
        # moto omits <return>true</return>; AWS always sends it, and failures raise earlier.
        if element.find(f"{{{NAMESPACE}}}return") is None:
            return True
        return bool(super()._get_boolean(element))

    # -- internals -----------------------------------------------------------------------------

    def _zone(self) -> str:
        if self._availability_zone is None:
            zones = self.ex_list_availability_zones(only_available=True)
            if not zones:
                raise EC2APIError("NoAvailabilityZone", f"{self.region_name} offers no zone")
            self._availability_zone = sorted(zone.name for zone in zones)[0]
        return self._availability_zone

    def _find_live_instance(self, tags: dict[str, str]) -> Node | None:
        identity = {NAME_TAG: tags[NAME_TAG], CONSTELLATION_TAG: tags[CONSTELLATION_TAG]}
        found = self.ex_list_nodes_by_tags(identity)
        if len(found) > 1:
            ids = ", ".join(sorted(str(node.id) for node in found))
            raise NameInUseError(f"several live instances are named {identity}: {ids}")
        return found[0] if found else None

    def _check_existing(
        self, node: Node, network: EC2ConstellationNetwork, private_ip: str | None
    ) -> Node:
        if node.extra.get("subnet_id") != network.subnet_id or (
            private_ip is not None and private_ip not in node.private_ips
        ):
            raise NameInUseError(
                f"instance {node.id} named {node.name!r} exists with other settings "
                f"(subnet {node.extra.get('subnet_id')}, addresses {node.private_ips})"
            )
        return node
