"""Benchmark the local provider: a network + N hosts created at once, memory per host, destroy.

Run as root: `.venv/bin/python bench/local_hosts.py [--nodes 4] [--init systemd|minimal|both]`.
"""

import argparse
import os
import shutil
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey
from cryptography.hazmat.primitives.serialization import Encoding, PublicFormat
from libcloud.compute.base import Node, NodeAuthSSHKey

from provisioners.local import netns, processes
from provisioners.local.driver import LocalNodeDriver


@dataclass
class Figures:
    """What one round measured."""

    init: str
    nodes: int
    create_seconds: float
    destroy_seconds: float
    pss_mib_per_host: float
    tmpfs_mib_per_host: float


def host_pss_kib(node: Node) -> int:
    """Return the PSS of every process of a host, its launcher included."""
    pids = set(netns.namespace_pids(node.extra["netns"]))
    if node.extra["launcher_pid"] is not None:
        pids.add(node.extra["launcher_pid"])
    return sum(processes.proportional_memory_kib(pid) for pid in pids)


def tmpfs_used_kib(directory: Path) -> int:
    """Return the bytes used on the filesystem holding directory, in KiB."""
    stats = os.statvfs(directory)
    return (stats.f_blocks - stats.f_bfree) * stats.f_frsize // 1024


def run_round(driver: LocalNodeDriver, init: str, count: int, settle: float) -> Figures:
    """Create a network and count hosts at once, measure, destroy them at once."""
    public_key = (
        Ed25519PrivateKey.generate()
        .public_key()
        .public_bytes(Encoding.OpenSSH, PublicFormat.OpenSSH)
    )
    auth = NodeAuthSSHKey(public_key.decode())
    started = time.monotonic()
    network = driver.ex_create_network(f"bench-{init}")
    with ThreadPoolExecutor(max_workers=count) as pool:
        futures = [
            pool.submit(
                driver.create_node, f"bench-{init}-{index}", None, None, auth=auth,
                ex_network=network, ex_public=index == 0, ex_init=init,
            )
            for index in range(count)
        ]  # fmt: skip
        nodes = [future.result() for future in futures]
    create_seconds = time.monotonic() - started
    # Let late boot jobs (journald flush, logind, user sessions) finish before measuring.
    time.sleep(settle)
    pss = sum(host_pss_kib(node) for node in nodes) / count
    tmpfs = tmpfs_used_kib(driver.hosts_dir) / count
    started = time.monotonic()
    with ThreadPoolExecutor(max_workers=count) as pool:
        assert all(pool.map(driver.destroy_node, nodes))
    driver.ex_destroy_network(network)
    destroy_seconds = time.monotonic() - started
    return Figures(
        init=init,
        nodes=count,
        create_seconds=create_seconds,
        destroy_seconds=destroy_seconds,
        pss_mib_per_host=pss / 1024,
        tmpfs_mib_per_host=tmpfs / 1024,
    )


def main() -> int:
    """Parse arguments, run the rounds, print the figures."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--nodes", type=int, default=4)
    parser.add_argument("--init", choices=["systemd", "minimal", "both"], default="both")
    parser.add_argument("--rounds", type=int, default=1)
    parser.add_argument("--settle", type=float, default=3.0, help="seconds before measuring RAM")
    args = parser.parse_args()
    if os.geteuid() != 0:
        print("bench/local_hosts.py needs root", file=sys.stderr)
        return 2
    modes = ["systemd", "minimal"] if args.init == "both" else [args.init]
    state_dir = Path(tempfile.mkdtemp(prefix="cloudsim-bench-local-"))
    driver = LocalNodeDriver(state_dir=str(state_dir), prefix=f"csb{os.getpid()}")
    results: list[Figures] = []
    try:
        for _ in range(args.rounds):
            for init in modes:
                results.append(run_round(driver, init, args.nodes, args.settle))
    finally:
        for node in driver.list_nodes():
            driver.destroy_node(node)
        for network in driver.ex_list_networks():
            driver.ex_destroy_network(network)
        shutil.rmtree(state_dir)
    header = ["init", "hosts", "create s", "destroy s", "PSS MiB/host", "tmpfs MiB/host"]
    print(f"{header[0]:8} {header[1]:>5} {header[2]:>9} {header[3]:>9} {header[4]:>12} "
          f"{header[5]:>14}")  # fmt: skip
    for figures in results:
        print(
            f"{figures.init:8} {figures.nodes:5d} {figures.create_seconds:9.2f} "
            f"{figures.destroy_seconds:9.2f} {figures.pss_mib_per_host:12.1f} "
            f"{figures.tmpfs_mib_per_host:14.1f}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
