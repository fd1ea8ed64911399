"""The registry and the base driver: one interface, its defaults, settings checked first."""

from __future__ import annotations

from pathlib import Path

import pytest
from libcloud.compute.base import Node
from libcloud.compute.providers import get_driver
from libcloud.compute.types import NodeState

from provisioners.providers.base import BEHIND_PUBLIC_MACHINE, CloudSimNodeDriver
from provisioners.providers.errors import SettingsError
from provisioners.providers.registry import PROVIDERS, provider, register_drivers
from provisioners.remote.ssh import HostKeys, Route


def test_every_provider_is_a_cloudsim_driver_known_to_libcloud() -> None:
    register_drivers()
    register_drivers()
    for spec in PROVIDERS.values():
        assert issubclass(get_driver(spec.libcloud_name), CloudSimNodeDriver), spec.name  # type: ignore[arg-type]
    assert sorted(PROVIDERS) == ["ec2", "local", "servers"]


def test_settings_are_checked_before_a_driver_is_made(tmp_path: Path) -> None:
    with pytest.raises(SettingsError, match="unknown provider 'mars'; known: local, ec2"):
        provider("mars")
    with pytest.raises(SettingsError, match="ec2 needs secret_key, image"):
        provider("ec2").open({"access_key": "a", "region": "us-east-1"}, tmp_path)
    with pytest.raises(SettingsError, match="endpoint must be an http"):
        provider("ec2").check(
            {"access_key": "a", "secret_key": "s", "region": "r", "image": "i", "endpoint": "ftp:x"}
        )
    with pytest.raises(SettingsError, match="servers inventory:"):
        provider("servers").check({"inventory": [{"name": "x"}]})
    with pytest.raises(SettingsError, match="unknown local settings: colour"):
        provider("local").check({"colour": "blue"})


class _Bare(CloudSimNodeDriver):
    """A driver with nothing but nodes: what the base class gives every provider."""

    def __init__(self, nodes: list[Node]) -> None:
        super().__init__(key="bare")
        self.nodes = nodes

    def list_nodes(self) -> list[Node]:
        return self.nodes


def _node(driver: CloudSimNodeDriver, name: str, state: NodeState, public: bool) -> Node:
    return Node(
        id=name,
        name=name,
        state=state,
        public_ips=["203.0.113.5"] if public else [],
        private_ips=["10.0.0.5"],
        driver=driver,
        extra={"tags": {"cloudsim:machine": name}},
    )


def test_the_base_driver_defaults() -> None:
    driver = _Bare([])
    router, sim = (
        _node(driver, "router", NodeState.RUNNING, True),
        _node(driver, "sim", NodeState.RUNNING, False),
    )
    driver.nodes = [router, sim]
    assert driver.ex_apply_firewall(None, [], []) == {}
    assert driver.ex_public_proxy_command("10.0.0.5", 22) is None
    assert driver.ex_list_nodes_by_tags({"cloudsim:machine": "sim"}) == [sim]
    assert driver.ex_ssh_route(router) == Route(host="203.0.113.5")
    assert driver.ex_ssh_route(sim) == Route(host="10.0.0.5", jump=BEHIND_PUBLIC_MACHINE)
    assert [n.name for n, _ in driver.wait_until_running([router, sim], timeout=1)] == [
        "router",
        "sim",
    ]
    driver.nodes = [router, _node(driver, "sim", NodeState.STOPPED, False)]
    with pytest.raises(Exception, match=r"will not run with private_ips: sim \(stopped\)"):
        driver.wait_until_running([router, sim], timeout=1)


def test_routes_round_trip_and_host_keys_are_looked_up_then_recorded() -> None:
    route = Route(host="10.0.0.5", user="admin", port=2222, proxy_command=("nc", "x"), jump="r")
    assert Route.from_json(route.to_json()) == route
    recorded: list[tuple[str, str]] = []
    keys = HostKeys(
        lookup={"a": "ssh-ed25519 AAAA"}.get, record=lambda n, k: recorded.append((n, k))
    )
    assert keys.get("a") == "ssh-ed25519 AAAA" and keys.get("b") is None
    keys.put("b", "ssh-ed25519 BBBB")
    assert keys.get("b") == "ssh-ed25519 BBBB" and recorded == [("b", "ssh-ed25519 BBBB")]
