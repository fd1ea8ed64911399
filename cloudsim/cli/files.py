"""Files a command reads: regular files only, bounded in size, UTF-8, or a one-line error.

A device (`/dev/zero`), a FIFO or a directory would make a plain read hang or fail with a
traceback; a file larger than any real document would fill memory before being refused.
"""

from __future__ import annotations

import os
import stat
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import click

MAX_FILE_BYTES = 4 * 1024 * 1024


@dataclass(frozen=True)
class LoadedText:
    """A file's name and its whole text, as TextFile read it."""

    name: str
    text: str

    def read(self) -> str:
        """Return the text (as a file object's read would)."""
        return self.text


def read_text(path: str | Path, max_bytes: int = MAX_FILE_BYTES) -> str:
    """Return a regular file's UTF-8 text, or raise ValueError saying why not ('-': stdin)."""
    if str(path) == "-":
        data = sys.stdin.buffer.read(max_bytes + 1)
    else:
        try:
            # O_NONBLOCK: opening a FIFO without a writer would wait for one
            fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
        except OSError as exc:
            raise ValueError(exc.strerror or str(exc)) from None
        with os.fdopen(fd, "rb") as file:
            if not stat.S_ISREG(os.fstat(fd).st_mode):
                raise ValueError("not a regular file")
            data = file.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise ValueError(f"larger than {max_bytes // 1024} KiB")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise ValueError("not UTF-8 text") from None


class TextFile(click.ParamType):
    """A click argument naming a file (or '-' for standard input) read as bounded UTF-8 text."""

    name = "file"

    def __init__(self, max_bytes: int = MAX_FILE_BYTES) -> None:
        self.max_bytes = max_bytes

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        if isinstance(value, LoadedText):
            return value
        shown = click.format_filename(value)
        try:
            return LoadedText(shown, read_text(value, self.max_bytes))
        except ValueError as exc:
            self.fail(f"{shown}: {exc}", param, ctx)
