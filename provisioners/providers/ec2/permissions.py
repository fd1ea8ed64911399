"""Security group permissions: FirewallRules in, EC2 IpPermissions out, and back from EC2."""

from collections import defaultdict
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from xml.etree.ElementTree import Element

from provisioners.providers.ec2.api import items, text
from provisioners.remote.firewall import SOURCE_ANY, SOURCE_LAN, SOURCE_PUBLIC, FirewallRule

ANY_IPV4 = "0.0.0.0/0"
ALL_PROTOCOLS = "-1"
# EC2 reports a protocol by number when it was given by number.
_PROTOCOL_NAMES = {"6": "tcp", "17": "udp", "1": "icmp"}
_TCP_UDP_ALL_PORTS = (0, 65535)
_ICMP_ALL_TYPES = (-1, -1)


@dataclass(frozen=True)
class Permission:
    """One allowed flow: a protocol and port range from one CIDR or one security group."""

    protocol: str
    from_port: int | None
    to_port: int | None
    cidr: str | None = None
    group_id: str | None = None

    def sort_key(self) -> tuple[str, int, int, str, str]:
        """Return a key that orders permissions stably (None sorts first)."""
        return (
            self.protocol,
            -2 if self.from_port is None else self.from_port,
            -2 if self.to_port is None else self.to_port,
            self.cidr or "",
            self.group_id or "",
        )


EGRESS_ALLOW_ALL = Permission(ALL_PROTOCOLS, None, None, cidr=ANY_IPV4)


def rule_permission(rule: FirewallRule, lan_cidr: str, group_ids: Mapping[str, str]) -> Permission:
    """Return the permission expressing rule, given the LAN's CIDR and each role's group id."""
    if rule.protocol == "all":
        protocol, ports = ALL_PROTOCOLS, None
    elif rule.protocol == "icmp":
        protocol, ports = "icmp", _ICMP_ALL_TYPES
    else:
        protocol, ports = rule.protocol, rule.ports or _TCP_UDP_ALL_PORTS
    from_port, to_port = ports if ports is not None else (None, None)
    if rule.source == SOURCE_LAN:
        return Permission(protocol, from_port, to_port, cidr=lan_cidr)
    if rule.source in (SOURCE_ANY, SOURCE_PUBLIC):
        # a group cannot leave the LAN out of "public": the host firewall does
        return Permission(protocol, from_port, to_port, cidr=ANY_IPV4)
    source_role = rule.source_role
    if source_role is None or source_role not in group_ids:
        raise KeyError(f"no security group for the source of {rule!r}")
    return Permission(protocol, from_port, to_port, group_id=group_ids[source_role])


def read_permissions(group: Element, direction: str) -> set[Permission]:
    """Return the permissions of a described security group; direction is ipPermissions[Egress]."""
    permissions: set[Permission] = set()
    for entry in items(group, f"{direction}/item"):
        raw_protocol = text(entry, "ipProtocol") or ALL_PROTOCOLS
        protocol = _PROTOCOL_NAMES.get(raw_protocol, raw_protocol)
        from_port, to_port = _port(text(entry, "fromPort")), _port(text(entry, "toPort"))
        if protocol == ALL_PROTOCOLS:
            from_port = to_port = None  # EC2 may echo -1 or nothing for "all traffic"
        for ip_range in items(entry, "ipRanges/item"):
            permissions.add(Permission(protocol, from_port, to_port, cidr=text(ip_range, "cidrIp")))
        for ip_range in items(entry, "ipv6Ranges/item"):
            permissions.add(
                Permission(protocol, from_port, to_port, cidr=text(ip_range, "cidrIpv6"))
            )
        for pair in items(entry, "groups/item"):
            permissions.add(
                Permission(protocol, from_port, to_port, group_id=text(pair, "groupId"))
            )
    return permissions


def permission_params(permissions: Iterable[Permission]) -> dict[str, str]:
    """Return IpPermissions.N.* parameters, one entry per protocol and port range."""
    grouped: dict[tuple[str, int | None, int | None], list[Permission]] = defaultdict(list)
    for permission in sorted(permissions, key=Permission.sort_key):
        grouped[(permission.protocol, permission.from_port, permission.to_port)].append(permission)
    params: dict[str, str] = {}
    for index, ((protocol, from_port, to_port), sources) in enumerate(grouped.items(), 1):
        root = f"IpPermissions.{index}"
        params[f"{root}.IpProtocol"] = protocol
        if from_port is not None and to_port is not None:
            params[f"{root}.FromPort"] = str(from_port)
            params[f"{root}.ToPort"] = str(to_port)
        counts = {"IpRanges": 0, "Ipv6Ranges": 0, "Groups": 0}
        for source in sources:
            if source.group_id is not None:
                key, field_name, value = "Groups", "GroupId", source.group_id
            elif source.cidr is not None and ":" in source.cidr:
                key, field_name, value = "Ipv6Ranges", "CidrIpv6", source.cidr
            elif source.cidr is not None:
                key, field_name, value = "IpRanges", "CidrIp", source.cidr
            else:
                continue  # a source we cannot express (a prefix list) is left alone
            counts[key] += 1
            params[f"{root}.{key}.{counts[key]}.{field_name}"] = value
    return params


def _port(value: str | None) -> int | None:
    return int(value) if value is not None else None
