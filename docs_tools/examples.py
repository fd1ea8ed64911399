"""Find the shell and Python examples in the documentation, each with how it is to be run.

A fenced block whose language is `sh`, `bash` or `python` is an example. The HTML comment on
the line before it says what it runs against (docs/developers/docs.md explains each):

    <!-- example: cloudsim -->          a real CloudSim the test starts (the default)
    <!-- example: drcsim -->            a real simulator the test starts
    <!-- example: standalone -->        nothing: the block needs only this checkout
    <!-- example: skip REASON -->       cannot run here, for REASON (few, and named in the test)

`xfail REASON` after the mode (`<!-- example: drcsim xfail REASON -->`) says the example
fails today, for REASON, which quotes (in double quotes) the error it fails with: failing
otherwise, or passing, fails the test, so the mark goes once the example works.

Other blocks (`text`, `json`, `yaml`, no language) are output, synopses or data, not examples.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

LANGUAGES = {"sh": "sh", "bash": "sh", "python": "python"}
MODES = {"cloudsim", "drcsim", "standalone", "skip"}
_FENCE = re.compile(r"^(?P<indent> *)(?P<fence>```+|~~~+)\s*(?P<info>[^\s`{]*)")
_MARK = re.compile(r"^\s*<!--\s*example:\s*(?P<mode>\S+)\s*(?P<reason>.*?)\s*-->\s*$")


class ExampleError(Exception):
    """A documentation file marks an example in a way this collector does not know."""


@dataclass(frozen=True)
class Example:
    """One fenced block: where it is, its language, how to run it and its text."""

    path: str
    line: int
    language: str
    mode: str
    reason: str  # why it is skipped
    xfail: str  # why it fails today ("" when it must pass)
    code: str

    @property
    def id(self) -> str:
        return f"{self.path}:{self.line}"


def documentation_files(root: Path) -> list[Path]:
    """Return the READMEs and every page of docs/, the files whose examples must run."""
    files = [root / "README.md", root / "simulator" / "README.md", root / "router" / "README.md"]
    files += sorted((root / "docs").rglob("*.md"))
    return [f for f in files if f.is_file()]


def examples_in(path: Path, root: Path) -> list[Example]:
    """Return the examples of one Markdown file, in order."""
    found: list[Example] = []
    lines = path.read_text().splitlines()
    mark: tuple[str, str] | None = None  # the mode and the rest of the comment
    index = 0
    while index < len(lines):
        line = lines[index]
        fence = _FENCE.match(line)
        if fence is None:
            matched = _MARK.match(line)
            if matched is not None:
                mode = matched["mode"]
                if mode not in MODES:
                    raise ExampleError(f"{path}:{index + 1}: unknown example mode {mode!r}")
                mark = (mode, matched["reason"])
                if mode == "skip" and not mark[1]:
                    raise ExampleError(f"{path}:{index + 1}: a skipped example must say why")
            elif line.strip():
                mark = None
            index += 1
            continue
        indent, closing = len(fence["indent"]), fence["fence"]
        body: list[str] = []
        index += 1
        while index < len(lines) and not lines[index].strip().startswith(closing):
            body.append(lines[index][indent:])
            index += 1
        index += 1
        language = LANGUAGES.get(fence["info"].lower())
        if language is not None:
            mode, rest = mark or ("cloudsim", "")
            reason, xfail = (rest, "") if mode == "skip" else ("", _xfail(rest, path, index))
            start = index - len(body) - 1  # the opening fence's line, counted from 1
            code = "\n".join(body) + "\n"
            where = str(path.relative_to(root))
            found.append(Example(where, start, language, mode, reason, xfail, code))
        mark = None
    return found


def _xfail(rest: str, path: Path, index: int) -> str:
    if not rest:
        return ""
    word, _, reason = rest.partition(" ")
    if word != "xfail" or reason.count('"') < 2:
        raise ExampleError(f'{path}:{index}: expected `xfail REASON ("error")`, not {rest!r}')
    return reason.strip()


def all_examples(root: Path) -> list[Example]:
    """Return every example of the documentation, README first."""
    return [e for path in documentation_files(root) for e in examples_in(path, root)]
