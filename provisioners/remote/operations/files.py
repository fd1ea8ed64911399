"""Directories and files (from content or from machine templates)."""

from __future__ import annotations

import hashlib
import shlex
from collections.abc import Iterator, Mapping

from provisioners.remote.facts import PathFact, PathState
from provisioners.remote.operations.base import Command, Operation, Step, Upload, chown_spec
from provisioners.remote.operations.errors import OperationError
from provisioners.remote.operations.templates import MachineTemplates


def _check_absolute(path: str) -> str:
    if not path.startswith("/"):
        raise ValueError(f"remote paths must be absolute: {path!r}")
    return path


def _check_mode(mode: int) -> int:
    if not 0 <= mode <= 0o7777:
        raise ValueError(f"not a file mode: {mode:o}")
    return mode


def plan_attributes(
    path: str, state: PathState, mode: int | None, owner: str | None, group: str | None
) -> Iterator[Step]:
    """Yield chmod/chown for an existing path whose mode or ownership differ."""
    if mode is not None and state.mode != mode:
        yield Command(f"chmod {mode:04o} {shlex.quote(path)}")
    wrong_owner = owner is not None and state.owner != owner
    wrong_group = group is not None and state.group != group
    if wrong_owner or wrong_group:
        spec = chown_spec(owner if wrong_owner else None, group if wrong_group else None)
        yield Command(f"chown {shlex.quote(spec)} {shlex.quote(path)}")


def plan_file_content(
    path: str,
    content: bytes,
    state: PathState,
    mode: int,
    owner: str | None,
    group: str | None,
) -> Iterator[Step]:
    """Yield an upload when the content differs, else only the attribute fixes needed."""
    if state.kind not in (None, "file"):
        raise OperationError(f"{path} is a {state.kind}, not a regular file")
    if state.kind is None or state.sha256 != hashlib.sha256(content).hexdigest():
        yield Upload(path, content, mode=mode, owner=owner, group=group)
        return
    yield from plan_attributes(path, state, mode, owner, group)


def directory(
    path: str, *, mode: int = 0o755, owner: str | None = None, group: str | None = None
) -> Operation:
    """Ensure a directory exists with the given mode and ownership."""
    _check_absolute(path)
    _check_mode(mode)

    def plan(state: PathState) -> Iterator[Step]:
        if state.kind is None:
            yield Command(f"mkdir -p -m {mode:04o} {shlex.quote(path)}")
            if owner is not None or group is not None:
                yield Command(f"chown {shlex.quote(chown_spec(owner, group))} {shlex.quote(path)}")
            return
        if state.kind != "directory":
            raise OperationError(f"{path} is a {state.kind}, not a directory")
        yield from plan_attributes(path, state, mode, owner, group)

    return Operation(f"directory {path}", (PathFact(path),), plan)


def file(
    path: str,
    content: str | bytes,
    *,
    mode: int = 0o644,
    owner: str | None = None,
    group: str | None = None,
) -> Operation:
    """Ensure a file has exactly this content, mode and ownership (uploaded only if it differs)."""
    _check_absolute(path)
    _check_mode(mode)
    data = content.encode() if isinstance(content, str) else content

    def plan(state: PathState) -> Iterator[Step]:
        return plan_file_content(path, data, state, mode, owner, group)

    return Operation(f"file {path}", (PathFact(path, checksum=True),), plan)


def absent(path: str) -> Operation:
    """Ensure nothing is at path (a file or an empty directory's place)."""
    _check_absolute(path)

    def plan(state: PathState) -> Iterator[Step]:
        if state.kind is not None:
            yield Command(f"rm -f -- {shlex.quote(path)}")

    return Operation(f"absent {path}", (PathFact(path),), plan)


def template(
    path: str,
    template_name: str,
    context: Mapping[str, object],
    *,
    mode: int = 0o644,
    owner: str | None = None,
    group: str | None = None,
    templates: MachineTemplates | None = None,
) -> Operation:
    """Ensure a file holds a machine template rendered with the context (rendered right away)."""
    rendered = (templates or MachineTemplates()).render(template_name, context)
    operation = file(path, rendered, mode=mode, owner=owner, group=group)
    return Operation(f"template {template_name} -> {path}", operation.facts, operation.plan)
