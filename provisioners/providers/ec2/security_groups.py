"""A constellation's firewall as one security group per role, reconciled to a rule list."""

from collections.abc import Sequence
from xml.etree.ElementTree import Element

from provisioners.providers.ec2.api import (
    NETWORK_TAG,
    ROLE_TAG,
    EC2Api,
    required_text,
    tag_specification,
)
from provisioners.providers.ec2.errors import InvalidRequestError
from provisioners.providers.ec2.networks import EC2ConstellationNetwork
from provisioners.providers.ec2.permissions import (
    EGRESS_ALLOW_ALL,
    Permission,
    permission_params,
    read_permissions,
    rule_permission,
)
from provisioners.remote.firewall import FirewallRule, check_role_name

_ALREADY_EXISTS = ["InvalidGroup.Duplicate"]
_ALREADY_ALLOWED = ["InvalidPermission.Duplicate"]
_ALREADY_REVOKED = ["InvalidPermission.NotFound"]


def group_name(network: EC2ConstellationNetwork, role: str) -> str:
    """Return the name of the security group of role's machines in network."""
    return f"{network.name}-{role}"


def apply_firewall(
    api: EC2Api,
    network: EC2ConstellationNetwork,
    rules: Sequence[FirewallRule],
    roles: Sequence[str],
) -> dict[str, str]:
    """Make each role's security group allow exactly what rules say; return role -> group id."""
    _check_request(rules, roles)
    groups = {role: _ensure_group(api, network, role) for role in roles}
    group_ids = {role: required_text(group, "groupId") for role, group in groups.items()}
    for role, group in groups.items():
        wanted = {
            rule_permission(rule, network.cidr, group_ids) for rule in rules if rule.to_role == role
        }
        _reconcile(
            api, group_ids[role], "Ingress", read_permissions(group, "ipPermissions"), wanted
        )
        egress = read_permissions(group, "ipPermissionsEgress")
        if EGRESS_ALLOW_ALL not in egress:
            _authorize(api, group_ids[role], "Egress", {EGRESS_ALLOW_ALL})
    return group_ids


def ensure_group_id(api: EC2Api, network: EC2ConstellationNetwork, role: str) -> str:
    """Return the id of role's security group, creating it empty (nothing allowed in) if absent."""
    try:
        check_role_name("ex_role", role)
    except ValueError as error:
        raise InvalidRequestError(str(error)) from None
    return required_text(_ensure_group(api, network, role), "groupId")


def _check_request(rules: Sequence[FirewallRule], roles: Sequence[str]) -> None:
    for role in roles:
        try:
            check_role_name("roles", role)
        except ValueError as error:
            raise InvalidRequestError(str(error)) from None
    if len(set(roles)) != len(roles):
        raise InvalidRequestError(f"roles must not repeat a role, got {list(roles)}")
    for rule in rules:
        if not isinstance(rule, FirewallRule):
            raise InvalidRequestError(f"rules must hold FirewallRule objects, got {rule!r}")
        if rule.to_role not in roles:
            raise InvalidRequestError(f"rule to_role {rule.to_role!r} is not one of roles {roles}")
        if rule.source_role is not None and rule.source_role not in roles:
            raise InvalidRequestError(
                f"rule source {rule.source!r} names a role that is not one of roles {roles}"
            )


def _find_group(api: EC2Api, network: EC2ConstellationNetwork, role: str) -> Element | None:
    found = api.describe(
        "DescribeSecurityGroups",
        "securityGroupInfo",
        {"vpc-id": network.id, "group-name": group_name(network, role)},
    )
    return found[0] if found else None


def _ensure_group(api: EC2Api, network: EC2ConstellationNetwork, role: str) -> Element:
    group = _find_group(api, network, role)
    if group is not None:
        return group
    tags = {NETWORK_TAG: network.name, ROLE_TAG: role, "Name": group_name(network, role)}
    # A concurrent apply may create it between our look-up and this call: then reuse theirs.
    api.call_ignoring(
        _ALREADY_EXISTS,
        "CreateSecurityGroup",
        {
            "GroupName": group_name(network, role),
            "GroupDescription": f"CloudSim {network.name}: machines of role {role}",
            "VpcId": network.id,
            **tag_specification("security-group", tags),
        },
    )
    group = _find_group(api, network, role)
    if group is None:
        raise InvalidRequestError(f"security group {group_name(network, role)} vanished")
    return group


def _reconcile(
    api: EC2Api,
    group_id: str,
    direction: str,
    current: set[Permission],
    wanted: set[Permission],
) -> None:
    # Authorize first so that a changed rule never leaves a window with neither version.
    if wanted - current:
        _authorize(api, group_id, direction, wanted - current)
    if current - wanted:
        _change(
            api, f"RevokeSecurityGroup{direction}", _ALREADY_REVOKED, group_id, current - wanted
        )


def _authorize(api: EC2Api, group_id: str, direction: str, permissions: set[Permission]) -> None:
    _change(api, f"AuthorizeSecurityGroup{direction}", _ALREADY_ALLOWED, group_id, permissions)


def _change(
    api: EC2Api, action: str, done_codes: list[str], group_id: str, permissions: set[Permission]
) -> None:
    answer = api.call_ignoring(
        done_codes, action, {"GroupId": group_id, **permission_params(permissions)}
    )
    if answer is not None:
        return
    # EC2 refuses a whole batch if one entry was done concurrently: redo them one by one.
    for permission in sorted(permissions, key=Permission.sort_key):
        api.call_ignoring(
            done_codes, action, {"GroupId": group_id, **permission_params([permission])}
        )
