"""CloudSim's wheel carries what it reads as package data: kinds, templates, migrations."""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

import pytest


def test_the_wheel_contains_kinds_templates_and_migrations(
    pytestconfig: pytest.Config, tmp_path: Path
) -> None:
    root = pytestconfig.rootpath
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", "-w", str(tmp_path), root],
        check=True,
        capture_output=True,
    )
    (wheel,) = tmp_path.glob("cloudsim-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    tracked = subprocess.run(
        ["git", "-C", str(root), "ls-files", "constellations/kinds", "templates", "migrations"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.split()
    assert len(tracked) > 40
    missing = [name for name in tracked if name not in names]
    assert not missing
