"""Team instance tests on the local provider: the constellation tests' app and worker, on a
prefix and networks of their own."""

from __future__ import annotations

import os
from collections.abc import Callable

import pytest

from cloudsim.config import Config
from tests.launched_constellations.conftest import (  # noqa: F401 (fixtures used here)
    constellations_app,
    constellations_worker,
)

PREFIX = f"ti{os.getpid() % 100000}"


@pytest.fixture
def constellations_config(make_config: Callable[..., Config]) -> Config:
    if os.geteuid() != 0:
        pytest.fail("team instance tests need root (the local provider makes namespaces)")
    return make_config(
        local_prefix=PREFIX,
        local_subnet_pool="10.218.0.0/16",
        local_public_cidr="198.18.18.0/24",
        job_lease_seconds=5,
    )
