"""Thin helpers over the EC2 query API: actions, numbered parameters, filters, tags, XML."""

from collections.abc import Iterable, Mapping
from typing import Any
from xml.etree.ElementTree import Element

from libcloud.compute.drivers.ec2 import NAMESPACE
from libcloud.utils.xml import findall, findtext

from provisioners.providers.ec2.errors import EC2APIError

NETWORK_TAG = "cloudsim:network"
CONSTELLATION_TAG = "cloudsim:constellation"
ROLE_TAG = "cloudsim:role"
NAME_TAG = "Name"

FilterValues = str | list[str]


class EC2Api:
    """Send EC2 query actions through a libcloud EC2 driver's signed connection."""

    def __init__(self, driver: Any) -> None:
        self.driver = driver

    def call(self, action: str, params: Mapping[str, str] | None = None) -> Element:
        """Send action with params and return the parsed XML answer."""
        request_params = {"Action": action, **(params or {})}
        response = self.driver.connection.request(self.driver.path, params=request_params)
        return response.object  # type: ignore[no-any-return]

    def call_ignoring(
        self, codes: Iterable[str], action: str, params: Mapping[str, str] | None = None
    ) -> Element | None:
        """Send action like call(), returning None when EC2 answers with one of codes."""
        try:
            return self.call(action, params)
        except EC2APIError as error:
            if error.code in set(codes):
                return None
            raise

    def describe(
        self, action: str, set_name: str, filters: Mapping[str, FilterValues] | None = None
    ) -> list[Element]:
        """Send a Describe* action with filters and return the items of its result set."""
        answer = self.call(action, filter_params(filters or {}))
        return items(answer, f"{set_name}/item")


def numbered(prefix: str, values: Iterable[str]) -> dict[str, str]:
    """Return {prefix.1: first, prefix.2: second, ...} (EC2 lists count from 1)."""
    return {f"{prefix}.{index}": value for index, value in enumerate(values, 1)}


def filter_params(filters: Mapping[str, FilterValues]) -> dict[str, str]:
    """Return Filter.N.Name / Filter.N.Value.M parameters for filters."""
    params: dict[str, str] = {}
    for index, (name, values) in enumerate(filters.items(), 1):
        params[f"Filter.{index}.Name"] = name
        value_list = [values] if isinstance(values, str) else values
        params.update(numbered(f"Filter.{index}.Value", value_list))
    return params


def tag_specification(resource_type: str, tags: Mapping[str, str]) -> dict[str, str]:
    """Return TagSpecification parameters that tag a resource in the call that creates it."""
    root = "TagSpecification.1"
    params = {f"{root}.ResourceType": resource_type}
    for index, (key, value) in enumerate(tags.items(), 1):
        params[f"{root}.Tag.{index}.Key"] = key
        params[f"{root}.Tag.{index}.Value"] = value
    return params


def tag_params(tags: Mapping[str, str | None]) -> dict[str, str]:
    """Return Tag.N.Key / Tag.N.Value parameters (a None value is left out)."""
    params: dict[str, str] = {}
    for index, (key, value) in enumerate(tags.items(), 1):
        params[f"Tag.{index}.Key"] = key
        if value is not None:
            params[f"Tag.{index}.Value"] = value
    return params


def items(element: Element, xpath: str) -> list[Element]:
    """Return the elements at xpath under element, in EC2's namespace."""
    return list(findall(element=element, xpath=xpath, namespace=NAMESPACE))


def text(element: Element, xpath: str) -> str | None:
    """Return the text at xpath under element, or None when it is absent."""
    value = findtext(element=element, xpath=xpath, namespace=NAMESPACE)
    return value if value else None


def required_text(element: Element, xpath: str) -> str:
    """Return the text at xpath under element; raise EC2APIError when EC2 left it out."""
    value = text(element, xpath)
    if value is None:
        raise EC2APIError("MalformedResponse", f"EC2's answer has no {xpath}")
    return value


def required_child(element: Element, tag: str) -> Element:
    """Return the child tag of an EC2 answer; raise EC2APIError when EC2 left it out."""
    child = element.find(f"{{{NAMESPACE}}}{tag}")
    if child is None:
        raise EC2APIError("MalformedResponse", f"EC2's answer has no {tag}")
    return child


def resource_tags(element: Element) -> dict[str, str]:
    """Return the tagSet of a described resource as a dict."""
    return {
        required_text(item, "key"): text(item, "value") or ""
        for item in items(element, "tagSet/item")
    }
