"""The driver as libcloud sees it: catalogue, registration, and the root requirement."""

import subprocess
import sys
from pathlib import Path

from libcloud.compute.providers import get_driver

from provisioners.providers.local.driver import LocalNodeDriver
from provisioners.providers.registry import register_drivers

from .local_support import needs_root

pytestmark = [needs_root]


def test_catalogue_has_one_size_image_and_location(driver: LocalNodeDriver) -> None:
    assert [size.id for size in driver.list_sizes()] == ["host"]
    assert [image.name for image in driver.list_images()] == ["debian-12 (this machine's root)"]
    assert [location.id for location in driver.list_locations()] == ["localhost"]


def test_register_makes_the_driver_available_by_name() -> None:
    register_drivers()
    register_drivers()
    assert get_driver("local") is LocalNodeDriver


def test_a_non_root_caller_is_told_that_root_is_needed(scratch: Path) -> None:
    script = (
        "from provisioners.providers.local.driver import LocalNodeDriver\n"
        f"LocalNodeDriver(state_dir={str(scratch)!r}).list_nodes()\n"
    )
    result = subprocess.run(
        [
            "setpriv",
            "--reuid=65534",
            "--regid=65534",
            "--clear-groups",
            sys.executable,
            "-B",
            "-c",
            script,
        ],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode != 0
    assert "NotRootError: the local provider needs root (running as uid 65534)" in result.stderr
    assert list(scratch.iterdir()) == []
