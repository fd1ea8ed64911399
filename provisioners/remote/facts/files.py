"""Facts about paths: kind, mode, owner and content checksum."""

from __future__ import annotations

import shlex
from dataclasses import dataclass
from typing import Literal

from provisioners.remote.facts.base import Fact

PathKind = Literal["file", "directory", "link", "other"]
_KINDS: frozenset[str] = frozenset({"file", "directory", "link", "other"})


@dataclass(frozen=True)
class PathState:
    """What exists at a path (kind None = nothing)."""

    kind: PathKind | None
    mode: int | None = None
    owner: str | None = None
    group: str | None = None
    sha256: str | None = None  # regular files only, when asked for

    @classmethod
    def absent(cls) -> PathState:
        """Return the state of a path where nothing exists."""
        return cls(kind=None)


@dataclass(frozen=True)
class PathFact(Fact[PathState]):
    """Read what is at a path, without following a final symlink."""

    path: str
    checksum: bool = False

    @property
    def command(self) -> str:
        """Return the probe: kind, then stat, then (for files) sha256sum."""
        quoted = shlex.quote(self.path)
        checksum = f'if [ "$k" = file ]; then sha256sum -- {quoted}; fi' if self.checksum else ":"
        return (
            f"if [ -L {quoted} ]; then k=link; elif [ -d {quoted} ]; then k=directory; "
            f"elif [ -f {quoted} ]; then k=file; elif [ -e {quoted} ]; then k=other; "
            f"else echo absent; exit 0; fi; "
            f"printf '%s ' \"$k\"; stat -c '%a %U %G' -- {quoted}; {checksum}"
        )

    def parse(self, stdout: str, exit_code: int) -> PathState:
        """Parse "absent" or "KIND MODE OWNER GROUP" plus an optional checksum line."""
        lines = stdout.splitlines()
        if lines[0] == "absent":
            return PathState.absent()
        kind, mode, owner, group = lines[0].split()
        if kind not in _KINDS:
            raise ValueError(f"unknown path kind {kind!r}")
        sha256 = None
        if self.checksum and kind == "file":
            # sha256sum prefixes a backslash when the file name needs escaping
            sha256 = lines[1].split()[0].lstrip("\\")
        return PathState(
            kind=kind,  # type: ignore[arg-type]
            mode=int(mode, 8),
            owner=owner,
            group=group,
            sha256=sha256,
        )
