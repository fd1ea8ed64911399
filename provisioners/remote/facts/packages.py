"""Facts about installed Debian packages."""

from __future__ import annotations

import re
import shlex
from dataclasses import dataclass

from provisioners.remote.facts.base import Fact

# Debian policy 5.6.1 package names, optionally qualified by an architecture
DEBIAN_PACKAGE_NAME = re.compile(r"^[a-z0-9][a-z0-9+.-]+(:[a-z0-9-]+)?$")


@dataclass(frozen=True)
class DebPackagesFact(Fact[dict[str, str | None]]):
    """Map each named package to its installed version, or None when it is not installed."""

    names: tuple[str, ...]
    # dpkg-query exits 1 when some name is unknown; the answer is still complete
    ok_exit_codes = frozenset({0, 1})

    def __post_init__(self) -> None:
        if not self.names:
            raise ValueError("no package names given")
        for name in self.names:
            if not DEBIAN_PACKAGE_NAME.match(name):
                raise ValueError(f"not a Debian package name: {name!r}")

    @property
    def command(self) -> str:
        """Return a dpkg-query listing status and version of each package."""
        fields = shlex.quote(r"${Package}\t${db:Status-Abbrev}\t${Version}\n")
        return f"dpkg-query -W -f={fields} -- {shlex.join(self.names)}"

    def parse(self, stdout: str, exit_code: int) -> dict[str, str | None]:
        """Parse tab-separated name, status abbreviation and version lines."""
        installed: dict[str, str | None] = dict.fromkeys(self.names)
        for line in stdout.splitlines():
            name, status, version = line.split("\t")
            # "ii" = wanted install, installed; anything else (rc, un, iF...) is not usable
            if status.strip() == "ii":
                for wanted in self.names:
                    if wanted.split(":")[0] == name:
                        installed[wanted] = version
        return installed
