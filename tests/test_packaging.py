"""CloudSim's wheel carries what it reads as package data: kinds, templates, migrations, the
local provider's measured host memory."""

from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest


def test_the_wheel_contains_kinds_templates_and_migrations(
    pytestconfig: pytest.Config, tmp_path: Path
) -> None:
    root = pytestconfig.rootpath
    # Built from a copy of the tracked files: setuptools builds in the source folder.
    source = tmp_path / "source"
    for name in _git(root, "ls-files"):
        if (root / name).is_file():
            (source / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(root / name, source / name)
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(tmp_path), source],
        check=True,
        capture_output=True,
    )
    (wheel,) = tmp_path.glob("cloudsim-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    tracked = _git(
        root,
        "ls-files",
        "constellations/kinds",
        "templates",
        "migrations",
        "provisioners/providers/local/host_memory.json",
    )
    assert len(tracked) > 40
    missing = [name for name in tracked if name not in names]
    assert not missing


def _git(root: Path, *args: str) -> list[str]:
    return subprocess.run(
        ["git", "-C", str(root), *args], check=True, capture_output=True, text=True
    ).stdout.split()
