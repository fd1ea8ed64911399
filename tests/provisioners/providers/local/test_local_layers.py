"""Image layers: installed once on this machine, seen by every later host, written by none."""

from collections.abc import Callable
from pathlib import Path

import pytest
from libcloud.compute.base import Node

from provisioners.providers.local.driver import LocalNodeDriver

from .local_support import HostShell, SshKey, create_host, needs_root

pytestmark = [pytest.mark.hosts, needs_root]

LAYER_FILE = "/opt/cloudsim-layer-test/file"


def test_a_layer_is_made_once_and_shared_read_only_by_later_hosts(
    driver: LocalNodeDriver, ssh_key: SshKey, shells: Callable[[Node, SshKey], HostShell]
) -> None:
    command = f"mkdir -p {Path(LAYER_FILE).parent} && echo shared > {LAYER_FILE}"
    network = driver.ex_create_network("layers")
    nodes = []
    try:
        assert driver.ex_image_layer("layer-test", command) is True
        assert driver.ex_image_layer("layer-test", "false") is False  # made already: not run
        assert not Path(LAYER_FILE).exists()  # the controller's own root is untouched
        nodes = [
            create_host(driver, name, network, ssh_key, ex_init="minimal")
            for name in ("layer-a", "layer-b")
        ]
        a, b = (shells(node, ssh_key) for node in nodes)
        assert a.check(f"cat {LAYER_FILE}") == "shared\n"
        a.check(f"echo mine > {LAYER_FILE}")
        assert a.check(f"cat {LAYER_FILE}") == "mine\n"
        assert b.check(f"cat {LAYER_FILE}") == "shared\n"  # a's write stayed a's
    finally:
        for node in nodes:
            driver.destroy_node(node)
        driver.ex_destroy_network(network)
    if not driver.list_nodes():
        assert not (driver.hosts_dir / ".layers").exists()  # gone with the last host's tmpfs
