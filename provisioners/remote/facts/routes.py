"""The machine's default IPv4 route."""

from __future__ import annotations

from provisioners.remote.facts.base import Fact


class DefaultRouteFact(Fact[str | None]):
    """The gateway address of the default route, or None when there is none."""

    @property
    def command(self) -> str:
        return "ip -4 route show default"

    def parse(self, stdout: str, exit_code: int) -> str | None:
        words = stdout.split()
        return words[words.index("via") + 1] if "via" in words else None
