"""Read CloudSim's own source: where a lifecycle's states are assigned."""

from __future__ import annotations

import re
from pathlib import Path

import cloudsim

PACKAGE = Path(cloudsim.__file__).parent


def state_assignments(states: tuple[str, ...], allowed: tuple[str, ...]) -> list[str]:
    """Return `file:line: code` for every assignment of one of `states` outside `allowed` files."""
    # "= RunState.X", "state=RunState.X" (keyword, UPDATE ... values), never "==" or "!="
    assigned = re.compile(rf"(?<![=!<>])=\s*(?:{'|'.join(states)})\.[A-Z]")
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        relative = path.relative_to(PACKAGE).as_posix()
        if relative.startswith("models/") or relative in allowed:
            continue  # the models declare the column defaults
        for number, line in enumerate(path.read_text().splitlines(), 1):
            if assigned.search(line):
                found.append(f"{relative}:{number}: {line.strip()}")
    return found
