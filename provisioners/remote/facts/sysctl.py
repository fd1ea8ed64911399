"""Facts about kernel parameters."""

from __future__ import annotations

import re
import shlex
from dataclasses import dataclass

from provisioners.remote.facts.base import Fact

SYSCTL_KEY = re.compile(r"^[a-z0-9_][a-z0-9_.-]*(/[a-z0-9_.-]+)*$", re.IGNORECASE)


def normalize_sysctl_value(value: str) -> str:
    """Return a value as sysctl compares it (multi-value parameters print with tabs)."""
    return " ".join(value.split())


@dataclass(frozen=True)
class SysctlFact(Fact[dict[str, str | None]]):
    """Map each kernel parameter to its current value, or None when the kernel lacks it."""

    keys: tuple[str, ...]

    def __post_init__(self) -> None:
        if not self.keys:
            raise ValueError("no sysctl keys given")
        for key in self.keys:
            if not SYSCTL_KEY.match(key):
                raise ValueError(f"not a sysctl key: {key!r}")

    @property
    def command(self) -> str:
        """Return a loop printing "ok KEY VALUE" or "missing KEY" per key."""
        return (
            f"for k in {shlex.join(self.keys)}; do "
            'if v=$(sysctl -n "$k" 2>/dev/null); then printf \'ok\\t%s\\t%s\\n\' "$k" "$v"; '
            "else printf 'missing\\t%s\\n' \"$k\"; fi; done"
        )

    def parse(self, stdout: str, exit_code: int) -> dict[str, str | None]:
        """Parse the loop's tab-separated lines."""
        values: dict[str, str | None] = dict.fromkeys(self.keys)
        for line in stdout.splitlines():
            status, key, *value = line.split("\t")
            if key not in values:
                raise ValueError(f"unexpected sysctl key {key!r}")
            if status == "ok":
                values[key] = normalize_sysctl_value(" ".join(value))
        return values
