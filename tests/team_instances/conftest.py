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
    hosts_config,
)

PREFIX = f"ti{os.getpid() % 100000}"


@pytest.fixture
def constellations_config(make_config: Callable[..., Config]) -> Config:
    return hosts_config(make_config, PREFIX, 218)
