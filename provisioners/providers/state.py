"""The one state store drivers keep on this controller: JSON documents under a folder.

Every document is written whole (a temporary file renamed over it, so readers never see half
of one), and one file lock per folder serialises read-modify-write between threads and
processes alike, so any later driver, in any process, finds what an earlier one made.
"""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from provisioners.providers.errors import StateError

LOCK_FILE = ".lock"


class JsonStateStore:
    """JSON documents named by their path under root; `lock()` guards changes."""

    def __init__(self, root: Path, error: type[Exception] = StateError) -> None:
        self.root = root
        self._error = error

    @contextmanager
    def lock(self) -> Iterator[None]:
        """Hold the folder's lock (between threads and processes alike)."""
        self.root.mkdir(parents=True, exist_ok=True)
        # A fresh open file description per holder: flock then excludes threads too.
        with open(self.root / LOCK_FILE, "a") as lock_file:
            fcntl.flock(lock_file, fcntl.LOCK_EX)
            try:
                yield
            finally:
                fcntl.flock(lock_file, fcntl.LOCK_UN)

    def read(self, name: str) -> dict[str, Any] | None:
        """Return a document, None when it does not exist (or was just deleted)."""
        path = self.root / name
        try:
            data = json.loads(path.read_text())
        except FileNotFoundError:
            return None
        except (OSError, ValueError) as error:
            raise self._error(f"state file {path} is damaged or unreadable: {error}") from error
        if not isinstance(data, dict):
            raise self._error(f"state file {path} is damaged: not a JSON object")
        return data

    def write(self, name: str, data: dict[str, Any]) -> None:
        """Write a document whole, creating its folder."""
        path = self.root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        # One temporary file per writer: threads and processes may write the same document.
        temporary = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.tmp")
        try:
            temporary.write_text(json.dumps(data, indent=2, sort_keys=True) + "\n")
            # A rename within one filesystem is atomic.
            os.replace(temporary, path)
        except OSError as error:
            temporary.unlink(missing_ok=True)
            raise self._error(f"cannot write {path}: {error}") from error

    def delete(self, name: str) -> None:
        """Remove a document, or a folder of them; no-op when absent."""
        path = self.root / name
        try:
            if path.is_dir():
                shutil.rmtree(path)
            else:
                path.unlink()
        except FileNotFoundError:
            return

    def names(self, pattern: str) -> list[str]:
        """Return the documents matching a glob pattern, sorted."""
        if not self.root.is_dir():
            return []
        return sorted(str(p.relative_to(self.root)) for p in self.root.glob(pattern))
