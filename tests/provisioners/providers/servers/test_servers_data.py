"""The servers provider from data: inventory validation, choosing servers, cleanup commands."""

from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Any

import pytest
from libcloud.compute.base import NodeAuthSSHKey
from libcloud.compute.providers import get_driver
from libcloud.compute.types import NodeState

from constellations.plans.common import FIREWALL_CHAIN
from constellations.plans.roles import (
    CLOUDSIM_ENV,
    CLOUDSIM_INSTANCE,
    CLOUDSIM_ROOT,
    CLOUDSIM_VENV,
    SIMULATOR_VENV,
)
from constellations.plans.router import (
    CSROUTER_COMMAND,
    CSROUTER_CONFIG,
    CSROUTER_SERVICE,
    CSROUTER_VENV,
    FORWARD_CHAIN,
    OCU_CHAIN,
    OPENVPN_DIR,
    PKI_DIR,
    SYSTEMD_DIR,
    VPN_INSTANCE,
    VPN_SERVICE,
)
from constellations.plans.software import REMOTE_ROOT
from provisioners.providers.registry import register_drivers
from provisioners.providers.servers import remote
from provisioners.providers.servers.claims import choose_server, node_state
from provisioners.providers.servers.driver import ServersNodeDriver
from provisioners.providers.servers.errors import (
    InvalidRequestError,
    InventoryError,
    NetworkNotFoundError,
    NoFreeServerError,
    ServersProviderError,
    StateError,
)
from provisioners.providers.servers.inventory import Inventory
from provisioners.providers.servers.state import (
    STATUS_FAILED,
    STATUS_PREPARING,
    STATUS_READY,
    NetworkClaim,
    ProcessRef,
    ServerClaim,
    ServersState,
    StateFile,
)
from provisioners.remote.operations.sysctl import DEFAULT_PERSIST_PATH

from .keys import KeyPair, make_key_pair

LOGIN = make_key_pair("inventory")


def entry(name: str, private_ip: str, **fields: Any) -> dict[str, Any]:
    """Return an inventory entry on lan-a (10.9.0.0/24) unless fields say otherwise."""
    return {
        "name": name,
        "address": private_ip,
        "private_ip": private_ip,
        "network": "lan-a",
        "cidr": "10.9.0.0/24",
        "private_key": LOGIN.private,
        **fields,
    }


def lab() -> list[dict[str, Any]]:
    """Return two LANs: lan-a with a public router box and two private boxes, lan-b with one."""
    return [
        entry("box1", "10.9.0.11", public_ip="198.51.100.1"),
        entry("box2", "10.9.0.12", capabilities=["gpu"]),
        entry("box3", "10.9.0.13"),
        entry("box4", "10.9.1.11", network="lan-b", cidr="10.9.1.0/24"),
    ]


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"name": "Box_1"}, "name"),
        ({"private_ip": "10.9.5.1"}, "private_ip"),
        ({"private_ip": "banana"}, "private_ip"),
        ({"cidr": "10.9.0.1/24"}, "cidr"),
        ({"private_key": "-----BEGIN OPENSSH PRIVATE KEY-----\nnope\n"}, "private_key"),
        ({"user": "root; rm -rf /"}, "user"),
        ({"port": 0}, "port"),
        ({"proxy_command": "ip netns exec x"}, "proxy_command"),
        ({"capabilities": ["g p u"]}, "capabilities"),
        ({"public_ip": "198.51.100.300"}, "public_ip"),
        ({"colour": "blue"}, "colour"),
        ({"address": None}, "address"),
    ],
)
def test_a_bad_entry_is_refused_naming_entry_and_field(change: dict[str, Any], field: str) -> None:
    bad = [entry("box1", "10.9.0.11"), {**entry("box2", "10.9.0.12"), **change}]
    bad[1] = {key: value for key, value in bad[1].items() if value is not None}
    with pytest.raises(InventoryError, match=rf"inventory entry 2\b.*field '{field}'") as caught:
        Inventory(bad)
    assert LOGIN.private not in str(caught.value)


def test_clashes_between_entries_are_refused() -> None:
    with pytest.raises(InventoryError, match=r"entry 2 \('box1'\): field 'name'"):
        Inventory([entry("box1", "10.9.0.11"), entry("box1", "10.9.0.12")])
    with pytest.raises(InventoryError, match=r"entry 2 .*field 'private_ip' 10.9.0.11 is taken"):
        Inventory([entry("box1", "10.9.0.11"), entry("box2", "10.9.0.11")])
    with pytest.raises(InventoryError, match=r"entry 2 .*field 'cidr'"):
        Inventory([entry("box1", "10.9.0.11"), entry("box2", "10.9.0.12", cidr="10.9.0.0/16")])
    with pytest.raises(InventoryError, match="no servers"):
        Inventory([])


def test_the_driver_refuses_a_bad_inventory(state_dir: Path) -> None:
    with pytest.raises(InventoryError, match=r"entry 1 \('box1'\): field 'network' is required"):
        ServersNodeDriver(
            inventory=[{k: v for k, v in entry("box1", "10.9.0.11").items() if k != "network"}],
            state_dir=str(state_dir),
        )
    assert issubclass(InventoryError, ServersProviderError)


def test_the_private_key_never_shows_in_a_repr() -> None:
    server = Inventory(lab()).servers[0]
    assert LOGIN.private not in repr(server)
    assert server.login_key_blob == LOGIN.blob


def test_registered_with_libcloud(state_dir: Path) -> None:
    register_drivers()
    register_drivers()
    driver_class = get_driver("servers")  # type: ignore[arg-type]  # stubs want a Provider enum
    driver = driver_class("servers", inventory=lab(), state_dir=str(state_dir))
    assert isinstance(driver, ServersNodeDriver)
    assert [size.id for size in driver.list_sizes()] == ["existing"]
    assert [image.id for image in driver.list_images()] == ["existing"]


def _network(lan: str = "lan-a") -> NetworkClaim:
    return NetworkClaim(name="c1", lan=lan, cidr="10.9.0.0/24", created_at=0.0)


def test_choose_server_prefers_the_address_and_keeps_public_boxes_for_public_nodes() -> None:
    inventory, state = Inventory(lab()), ServersState()

    def choose(private_ip: str | None, public: bool, capability: str | None = None) -> str:
        return choose_server(
            inventory,
            state,
            _network(),
            private_ip=private_ip,
            public=public,
            capability=capability,
        ).name

    assert choose("10.9.0.13", public=False) == "box3"
    # the only public box stays for the router, even when asked for by address
    assert choose("10.9.0.11", public=False) == "box2"
    assert choose("10.9.0.12", public=True) == "box1"
    assert choose(None, public=False, capability="gpu") == "box2"
    with pytest.raises(NoFreeServerError, match="capability 'gpu'"):
        choose(None, public=True, capability="gpu")


def test_networks_are_pre_made_and_handed_out_whole(state_dir: Path) -> None:
    driver = ServersNodeDriver(inventory=lab(), state_dir=str(state_dir))
    first = driver.ex_create_network("c1")
    assert (first.name, first.cidr, first.extra["lan"]) == ("c1", "10.9.0.0/24", "lan-a")
    assert driver.ex_create_network("c1") == first
    with pytest.raises(InvalidRequestError, match=r"exists on 10\.9\.0\.0/24"):
        driver.ex_create_network("c1", cidr="10.9.1.0/24")
    second = driver.ex_create_network("c2", cidr="10.9.1.0/24")
    assert second.extra["lan"] == "lan-b"
    with pytest.raises(NoFreeServerError, match="no free pre-made network for 'c3'"):
        driver.ex_create_network("c3")
    fresh = ServersNodeDriver(inventory=lab(), state_dir=str(state_dir))
    assert [network.name for network in fresh.ex_list_networks()] == ["c1", "c2"]
    assert fresh.ex_destroy_network(first)
    assert fresh.ex_destroy_network(first)
    with pytest.raises(NetworkNotFoundError):
        fresh.ex_get_network("c1")
    assert fresh.ex_create_network("c3").extra["lan"] == "lan-a"


def test_create_node_checks_its_arguments_before_claiming(state_dir: Path) -> None:
    driver = ServersNodeDriver(inventory=lab(), state_dir=str(state_dir))
    network = driver.ex_create_network("c1")
    auth = NodeAuthSSHKey(make_key_pair("constellation").public_line)
    with pytest.raises(InvalidRequestError, match="node name"):
        driver.create_node(name="bad_name", auth=auth, ex_network=network)
    with pytest.raises(InvalidRequestError, match="public key"):
        driver.create_node(name="c1-sim", auth=NodeAuthSSHKey("not a key"), ex_network=network)
    with pytest.raises(NetworkNotFoundError):
        driver.create_node(name="c1-sim", auth=auth, ex_network="c9")
    assert driver.list_nodes() == []
    assert all(server["status"] == "free" for server in driver.ex_list_servers())


def test_iptables_cleanup_deletes_jumps_then_chains() -> None:
    listing = "\n".join(
        [
            "-P INPUT ACCEPT",
            "-P FORWARD DROP",
            "-N CLOUDSIM-IN",
            "-N CLOUDSIM-FWD",
            "-N OTHER",
            "-A INPUT -j CLOUDSIM-IN",
            "-A INPUT -p tcp --dport 22 -j ACCEPT",
            '-A FORWARD -m comment --comment "cloud sim" -j CLOUDSIM-FWD',
            "-A OTHER -g CLOUDSIM-IN",
            "-A CLOUDSIM-IN -s 10.0.0.0/24 -j ACCEPT",
        ]
    )
    assert remote.iptables_cleanup("filter", listing) == [
        "iptables -w 10 -t filter -D INPUT -j CLOUDSIM-IN",
        "iptables -w 10 -t filter -D FORWARD -m comment --comment 'cloud sim' -j CLOUDSIM-FWD",
        "iptables -w 10 -t filter -D OTHER -g CLOUDSIM-IN",
        "iptables -w 10 -t filter -F CLOUDSIM-IN",
        "iptables -w 10 -t filter -F CLOUDSIM-FWD",
        "iptables -w 10 -t filter -X CLOUDSIM-IN",
        "iptables -w 10 -t filter -X CLOUDSIM-FWD",
    ]
    assert remote.iptables_cleanup("filter", "-P INPUT ACCEPT\n-A INPUT -j ACCEPT") == []
    raw = "-P PREROUTING ACCEPT\n-N CLOUDSIM-OCU\n-A PREROUTING -j CLOUDSIM-OCU"
    assert remote.iptables_cleanup("raw", raw) == [
        "iptables -w 10 -t raw -D PREROUTING -j CLOUDSIM-OCU",
        "iptables -w 10 -t raw -F CLOUDSIM-OCU",
        "iptables -w 10 -t raw -X CLOUDSIM-OCU",
    ]


def test_rule_listings_are_split_by_table() -> None:
    output = "*filter\n-P INPUT ACCEPT\n-N CLOUDSIM-IN\n*nat\n*raw\n-P OUTPUT ACCEPT\n"
    assert remote.parse_rule_listing(output) == {
        "filter": "-P INPUT ACCEPT\n-N CLOUDSIM-IN",
        "nat": "",
        "raw": "-P OUTPUT ACCEPT",
    }
    script = remote.list_rules_script()
    assert all(f"echo '*{table}'" in script for table in ("filter", "nat", "mangle", "raw"))


def test_cleanup_covers_what_the_deploy_plans_put_on_machines() -> None:
    assert all(
        c.startswith(remote.CHAIN_PREFIX) for c in (FIREWALL_CHAIN, FORWARD_CHAIN, OCU_CHAIN)
    )
    placed = [
        SIMULATOR_VENV,
        REMOTE_ROOT,
        CLOUDSIM_ROOT,
        CLOUDSIM_VENV,
        CLOUDSIM_ENV,
        CLOUDSIM_INSTANCE,
        CSROUTER_VENV,
        CSROUTER_CONFIG,
        CSROUTER_COMMAND,
        f"{PKI_DIR}/server.key",
        f"{OPENVPN_DIR}/{VPN_INSTANCE}.conf",
        f"{SYSTEMD_DIR}/{CSROUTER_SERVICE}.service",
        f"{SYSTEMD_DIR}/{VPN_SERVICE}.service.d/csrouter.conf",
        f"{SYSTEMD_DIR}/cloudsim.service",
        DEFAULT_PERSIST_PATH,
    ]
    uncovered = [
        path
        for path in placed
        if not any(path == p or path.startswith(p + "/") for p in remote.CLOUDSIM_PATHS)
    ]
    assert uncovered == []
    assert {f"{CSROUTER_SERVICE}.service", f"{VPN_SERVICE}.service"} <= set(remote.SERVICES)


def test_scripts_never_touch_the_login_key() -> None:
    server = Inventory(lab()).servers[0]
    other: KeyPair = make_key_pair("constellation")
    prepare = remote.prepare_script(server, "c1-router", LOGIN.public_line, [LOGIN.public_line])
    assert LOGIN.blob not in prepare
    cleanup = remote.cleanup_script(server, [LOGIN.public_line, other.public_line], {})
    assert LOGIN.blob not in cleanup and other.blob in cleanup
    assert "hostname box1\n" in cleanup
    # the key goes last: a failed step leaves it, so the terminate's retry can log in again
    assert cleanup.index(other.blob) > cleanup.index("hostname box1\n") > cleanup.index("rm -rf")


def test_a_claim_reads_pending_only_while_its_preparing_process_lives() -> None:
    gone = subprocess.Popen(["true"])
    gone.wait()
    dead = ProcessRef(gone.pid, 1)  # a start time no live process has

    def claim(status: str, creator: ProcessRef) -> ServerClaim:
        return ServerClaim(
            server="box1",
            node="c1-sim",
            network="c1",
            private_ip="10.9.0.11",
            public_ip=None,
            public_key=LOGIN.public_line,
            tags={},
            size="existing",
            status=status,
            created_at=0.0,
            creator=creator,
        )

    assert node_state(claim(STATUS_READY, dead)) == NodeState.RUNNING
    assert node_state(claim(STATUS_PREPARING, ProcessRef.current())) == NodeState.PENDING
    assert node_state(claim(STATUS_PREPARING, dead)) == NodeState.ERROR
    assert node_state(claim(STATUS_FAILED, ProcessRef.current())) == NodeState.ERROR


def test_the_state_file_survives_a_round_trip_and_refuses_damage(state_dir: Path) -> None:
    store = StateFile(state_dir)
    with store.transaction() as state:
        state.networks["c1"] = NetworkClaim(
            name="c1", lan="lan-a", cidr="10.9.0.0/24", created_at=1
        )
        state.host_keys["box1"] = "ssh-ed25519 AAAA"
    assert store.read().networks["c1"].lan == "lan-a"
    with pytest.raises(RuntimeError), store.transaction() as state:
        state.networks.clear()
        raise RuntimeError("a failed change is not written")
    assert "c1" in store.read().networks
    store.path.write_text("{not json")
    with pytest.raises(StateError, match="damaged"):
        store.read()
    assert issubclass(StateError, ServersProviderError)


def test_a_network_cidr_is_parsed(state_dir: Path) -> None:
    driver = ServersNodeDriver(inventory=lab(), state_dir=str(state_dir))
    with pytest.raises(InvalidRequestError, match="not an IPv4 network"):
        driver.ex_create_network("c1", cidr="10.9.0.0/33")
    assert driver.ex_create_network("c1", cidr="10.9.1.0/24").extra["lan"] == "lan-b"
