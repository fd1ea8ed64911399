"""Make the README's screenshot from the real pages: CloudSim started as `make run` starts it,
a few teams and tasks made with the documented commands, the dashboard in headless Chromium.

    .venv/bin/python -m docs_tools.screenshot [--out docs/images/dashboard.png]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

from playwright.sync_api import sync_playwright

from tests.support.up import cloudsim_up

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = "/usr/bin/chromium"
PASSWORD = "screenshot-admin-password"  # noqa: S105 (a throwaway CloudSim's, gone afterwards)
# What the dashboard shows: the commands an officer would type (docs/officers/competition.md)
SEASON = [
    ["team", "create", "Team 7"],
    ["team", "create", "Team 8"],
    ["team", "create", "Team 9"],
    ["user", "create", "--email", "pat@example.org", "--role", "user", "--team", "Team 7"],
    *(
        [
            "task",
            "add",
            "--name",
            name,
            "--world",
            world,
            "--config",
            "1",
            "--start",
            "2027-06-17 09:00",
            "--stop",
            "2027-06-17 12:00",
            "--time-zone",
            "Europe/Berlin",
            "--team",
            team,
        ]
        for name, world, team in (
            ("Walking 1", "vrc_task_2", "Team 7"),
            ("Walking 1", "vrc_task_2", "Team 8"),
            ("Driving 1", "vrc_task_1", "Team 9"),
        )
    ),
]


def main() -> None:
    """Start CloudSim in a temporary folder, fill it a little, save the dashboard as a PNG."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "images" / "dashboard.png")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="cloudsim-screenshot-") as folder:
        settings = {
            "CLOUDSIM_ADMIN_EMAIL": "admin@example.org",
            "CLOUDSIM_ADMIN_PASSWORD": PASSWORD,
        }
        with cloudsim_up(Path(folder), ROOT, **settings) as up:
            for command in SEASON:
                subprocess.run(
                    [sys.executable, "-m", "cloudsim.cli", *command],
                    env=up.env,
                    check=True,
                    capture_output=True,
                )
            with sync_playwright() as playwright:
                browser = playwright.chromium.launch(
                    executable_path=CHROMIUM, args=["--headless", "--no-sandbox"]
                )
                page = browser.new_page(viewport={"width": 1280, "height": 800})
                page.goto(f"http://{up.address}/login")
                page.get_by_label("E-mail").fill(up.env["CLOUDSIM_ADMIN_EMAIL"])
                page.get_by_label("Password").fill(PASSWORD)
                page.get_by_role("button", name="Log in").click()
                page.wait_for_url(f"http://{up.address}/")
                args.out.parent.mkdir(parents=True, exist_ok=True)
                page.screenshot(path=str(args.out))
                browser.close()
    print(args.out)


if __name__ == "__main__":
    main()
