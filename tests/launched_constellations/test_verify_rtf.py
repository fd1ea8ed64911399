"""Verification enforces real time: a simulator slower than the competition needs fails the
launch with the figure measured.

The self-test really runs (here: the local hosts do not see this checkout's virtualenv); a
stand-in on a real local host prints its answer, which verification reads over SSH.
"""

from __future__ import annotations

import os
import shlex
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

from cloudsim.error_codes import LAUNCH_SIM_SLOW
from cloudsim.launched_constellations.jobs import launch_error_code
from cloudsim.launched_constellations.verify import (
    VerificationFailed,
    selftest_attempt,
    selftest_failure,
)
from provisioners.providers.local import netns
from provisioners.providers.local.driver import LocalNodeDriver
from provisioners.remote.ssh import HostKeys, SSHExecutor, SSHTarget
from tests.support.lightweight_runs import Host, boot_hosts

pytestmark = pytest.mark.hosts
PREFIX = "csrtf"
DRCSIM = str(Path(sys.executable).parent / "drcsim")


@pytest.fixture(scope="module")
def sim() -> Iterator[Host]:
    if os.geteuid() != 0:
        pytest.skip("local hosts need root")
    scratch = Path(tempfile.mkdtemp(prefix=f"{PREFIX}-"))
    driver = LocalNodeDriver(
        state_dir=str(scratch / "state"),
        prefix=PREFIX,
        subnet_pool="10.233.0.0/16",
        public_cidr="198.18.33.0/24",
    )
    try:
        [host] = boot_hosts(driver, f"{PREFIX}-lan", ["sim"])
        yield host
    finally:
        for node in driver.list_nodes():
            driver.destroy_node(node)
        for network in driver.ex_list_networks():
            driver.ex_destroy_network(network)
        shutil.rmtree(scratch)
    assert netns.list_namespaces(f"{PREFIX}-") == []


def test_a_simulator_under_the_needed_rtf_fails_with_the_figure(sim: Host) -> None:
    proxy = sim.route["proxy_command"]
    assert isinstance(proxy, list)
    target = SSHTarget(
        name="sim", host=sim.node.private_ips[0], private_key=sim.keys.private, proxy_command=proxy
    )
    measured = (
        subprocess.run(
            [DRCSIM, "selftest", "--seconds", "1", "--min-rtf", "0", "--json"],
            capture_output=True,
            text=True,
            check=True,
        )
        .stdout.strip()
        .splitlines()[-1]
    )
    answer = f"echo {shlex.quote(measured)}"  # what `drcsim selftest --json` printed on sim
    with SSHExecutor(HostKeys()) as executor:
        # no machine steps this world at 1000 times real time: too slow for such a competition
        ok, found = selftest_attempt(executor, target, 1000.0, answer)()
        assert not ok and found.get("slow"), found
        assert 0 < found["rtf"] < 1000.0
        message = selftest_failure("sim", found)
        assert f"real-time factor of {found['rtf']}, under the 1000.0" in message
        # a machine that holds the needed factor passes
        passed, measured = selftest_attempt(executor, target, 0.01, answer)()
        assert passed and not measured.get("slow") and measured["rtf"] > 0.01
    failed = VerificationFailed(f"verification failed: {message}", LAUNCH_SIM_SLOW)
    assert launch_error_code(failed) == LAUNCH_SIM_SLOW
