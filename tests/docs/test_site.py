"""The documentation site builds with `mkdocs build --strict` (every link and anchor resolves,
every page is in the navigation), and its reference pages are the code's own."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from cloudsim.config import SETTINGS
from cloudsim.error_codes import CODES

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Build the site as `make docs` does, into a temporary folder."""
    out = tmp_path_factory.mktemp("site")
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    result = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    return out


def test_every_setting_is_on_the_configuration_page(site: Path) -> None:
    page = (site / "reference" / "configuration" / "index.html").read_text()
    missing = [name for name in SETTINGS if f"<code>{name}</code>" not in page]
    assert not missing


def test_every_error_code_is_on_its_page(site: Path) -> None:
    page = (site / "error-codes" / "index.html").read_text()
    assert [code for code in CODES if f"<code>{code}</code>" not in page] == []


def test_every_command_is_on_the_cli_page(site: Path) -> None:
    page = (site / "reference" / "cli" / "index.html").read_text()
    for command in ("cloudsim up", "cloudsim user update", "cloudsim constellation launch"):
        assert f"<code>{command}</code>" in page
    assert "--password-stdin" in page


def test_every_api_operation_is_on_the_api_page(site: Path) -> None:
    spec = json.loads((site / "reference" / "openapi.json").read_text())
    page = (site / "reference" / "api" / "index.html").read_text()
    operations = [
        f"{method.upper()} {path}"
        for path, ops in spec["paths"].items()
        for method in ops
        if method in {"get", "post", "put", "patch", "delete"}
    ]
    assert len(operations) > 40
    assert [op for op in operations if f"<code>{op}</code>" not in page] == []
