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
    expected = [
        *(p for p in (root / "constellations" / "kinds").glob("*.yaml")),
        *(
            p
            for p in (root / "templates").rglob("*")
            if p.is_file() and "__pycache__" not in str(p)
        ),
        *(p for p in (root / "migrations" / "versions").glob("*.py")),
        root / "migrations" / "env.py",
        root / "migrations" / "script.py.mako",
    ]
    missing = [str(p.relative_to(root)) for p in expected if str(p.relative_to(root)) not in names]
    assert not missing
