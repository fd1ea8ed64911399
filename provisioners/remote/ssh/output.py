"""Turn command output into masked log lines as it arrives."""

from __future__ import annotations

import codecs
from collections.abc import Callable, Iterable

#: Receives (machine name, one line of log) for every command, output line and event.
LogSink = Callable[[str, str], None]

MASK = "***"


class SecretMasker:
    """Replace every known secret string in a text with ***."""

    def __init__(self, secrets: Iterable[str] = ()) -> None:
        self._secrets: list[str] = []
        for secret in secrets:
            self.add(secret)

    def add(self, secret: str) -> None:
        """Start masking one more secret."""
        if secret and secret not in self._secrets:
            self._secrets.append(secret)
            # longest first, so a secret containing another is masked whole
            self._secrets.sort(key=len, reverse=True)

    def __call__(self, text: str) -> str:
        """Return the text with every secret replaced."""
        for secret in self._secrets:
            text = text.replace(secret, MASK)
        return text


class LineStream:
    """Collect one output stream and hand each complete line to a callback."""

    def __init__(self, on_line: Callable[[str], None]) -> None:
        self._on_line = on_line
        self._decoder = codecs.getincrementaldecoder("utf-8")(errors="replace")
        self._chunks: list[str] = []
        self._partial = ""

    def feed(self, data: bytes) -> None:
        """Take bytes as they arrive (lines and UTF-8 characters may be split anywhere)."""
        self._take(self._decoder.decode(data))

    def close(self) -> None:
        """Flush a last line that has no newline."""
        self._take(self._decoder.decode(b"", final=True))
        if self._partial:
            self._on_line(self._partial)
            self._partial = ""

    @property
    def text(self) -> str:
        """Return everything received so far, decoded."""
        return "".join(self._chunks)

    def _take(self, text: str) -> None:
        if not text:
            return
        self._chunks.append(text)
        *complete, self._partial = (self._partial + text).split("\n")
        for line in complete:
            self._on_line(line.removesuffix("\r"))
