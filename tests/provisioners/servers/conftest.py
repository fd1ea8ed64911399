"""Fixtures for the servers provider: state dirs and real "existing servers" made as local hosts.

The temporary directories are made with tempfile, not pytest's tmp_path: the latter sweeps
older pytest directories, and other suites' leftovers there can make that sweep warn.
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest


@pytest.fixture
def state_dir() -> Iterator[Path]:
    """Return an empty directory for one driver's state, removed afterwards."""
    directory = Path(tempfile.mkdtemp(prefix="cloudsim-servers-state-"))
    yield directory
    shutil.rmtree(directory)
