"""Benchmark the local provider: a network + N hosts created at once, memory per host, destroy.

Run as root: `.venv/bin/python -m bench.local_hosts [--nodes 4] [--init systemd|minimal|both]`.
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

from provisioners.providers.local import netns, processes
from provisioners.providers.local.driver import LocalNodeDriver


@dataclass
class Figures:
    """What one round measured."""

    init: str
    networks: int
    hosts: int
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


def run_round(
    driver: LocalNodeDriver, init: str, networks: int, per_network: int, settle: float
) -> Figures:
    """Create networks, each with per_network hosts, all at once; measure; destroy all at once."""
    public_key = (
        Ed25519PrivateKey.generate()
        .public_key()
        .public_bytes(Encoding.OpenSSH, PublicFormat.OpenSSH)
    )
    auth = NodeAuthSSHKey(public_key.decode())
    started = time.monotonic()
    lans = [driver.ex_create_network(f"bench-{init}-{n}") for n in range(networks)]
    with ThreadPoolExecutor(max_workers=networks * per_network) as pool:
        futures = [
            pool.submit(
                driver.create_node, f"{lan.name}-{index}", None, None, auth=auth,
                ex_network=lan, ex_public=index == 0, ex_init=init,
            )
            for lan in lans
            for index in range(per_network)
        ]  # fmt: skip
        nodes = [future.result() for future in futures]
    create_seconds = time.monotonic() - started
    # Let late boot jobs (journald flush, logind) finish before measuring memory.
    time.sleep(settle)
    pss = sum(host_pss_kib(node) for node in nodes) / len(nodes)
    tmpfs = tmpfs_used_kib(driver.hosts_dir) / len(nodes)
    started = time.monotonic()
    with ThreadPoolExecutor(max_workers=len(nodes)) as pool:
        assert all(pool.map(driver.destroy_node, nodes))
    for lan in lans:
        driver.ex_destroy_network(lan)
    destroy_seconds = time.monotonic() - started
    return Figures(
        init=init,
        networks=networks,
        hosts=len(nodes),
        create_seconds=create_seconds,
        destroy_seconds=destroy_seconds,
        pss_mib_per_host=pss / 1024,
        tmpfs_mib_per_host=tmpfs / 1024,
    )


def main() -> int:
    """Parse arguments, run the rounds, print the figures."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--nodes", type=int, default=4, help="hosts per network")
    parser.add_argument("--networks", type=int, default=1, help="networks created at once")
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
                results.append(run_round(driver, init, args.networks, args.nodes, args.settle))
    finally:
        leaked = driver.ex_sweep()
        shutil.rmtree(state_dir)
    if leaked:
        print(f"leaked (now removed): {leaked}", file=sys.stderr)
    print(
        f"{'init':8} {'networks':>8} {'hosts':>5} {'create s':>9} {'destroy s':>9} "
        f"{'PSS MiB/host':>12} {'tmpfs MiB/host':>14}"
    )
    for figures in results:
        print(
            f"{figures.init:8} {figures.networks:8d} {figures.hosts:5d} "
            f"{figures.create_seconds:9.2f} {figures.destroy_seconds:9.2f} "
            f"{figures.pss_mib_per_host:12.1f} {figures.tmpfs_mib_per_host:14.1f}"
        )
    return 1 if leaked else 0


if __name__ == "__main__":
    sys.exit(main())
