"""Every `cloudsim` command answers bad arguments and files with one error line and a non-zero
exit: arguments that are not UTF-8, files that are not UTF-8, devices, files over the limit.

The commands are enumerated from the click tree, so a new command is covered the day it lands.
"""

from __future__ import annotations

import os
import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path

import click
import pytest
from click.testing import Result

from cloudsim.cli import main
from cloudsim.cli.files import MAX_FILE_BYTES, TextFile
from tests.support.cli import migrated_cli
from tests.support.servers import RedisServer

# What click makes of the Latin-1 byte 0xE9 in argv on a UTF-8 system: a lone surrogate.
NOT_UTF8 = "caf\udce9"
MODES = ("not-utf8", "device", "huge")


def _commands(group: click.Group, path: tuple[str, ...] = ()) -> Iterator[tuple[str, ...]]:
    # through list_commands and get_command: `cloudsim`'s commands load when looked up
    context = click.Context(group)
    for name in group.list_commands(context):
        command = group.get_command(context, name)
        if isinstance(command, click.Group):
            yield from _commands(command, (*path, name))
        elif command is not None:
            yield (*path, name)


def _command(path: tuple[str, ...]) -> click.Command:
    command: click.Command | None = main
    for name in path:
        assert isinstance(command, click.Group)
        command = command.get_command(click.Context(command), name)
    assert command is not None
    return command


def _inputs(command: click.Command) -> list[click.Parameter]:
    """Return the parameters a person types text or a file name into."""
    return [
        p
        for p in command.params
        if not getattr(p, "is_flag", False)
        and p.name != "help"
        and (isinstance(p.type, TextFile) or p.type is click.STRING)
    ]


COMMANDS = [path for path in _commands(main) if _inputs(_command(path))]


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    tmp_path = tmp_path_factory.mktemp("files")
    latin1 = tmp_path / "latin1.yaml"
    latin1.write_bytes(b"name: caf\xe9\n")
    huge = tmp_path / "huge.yaml"
    with huge.open("wb") as handle:  # sparse: no disk spent on it
        handle.truncate(MAX_FILE_BYTES + 1)
    return {"not-utf8": str(latin1), "device": "/dev/zero", "huge": str(huge)}


@pytest.fixture(scope="module")
def run(
    tmp_path_factory: pytest.TempPathFactory, redis_server: RedisServer, encryption_key: str
) -> Callable[..., Result]:
    """Run a command on one migrated database (every command here must leave it unchanged)."""
    return migrated_cli(
        tmp_path_factory.mktemp("cli") / "instance",
        redis_server.url(0),
        encryption_key,
        CLOUDSIM_LOCAL_PREFIX=f"bi{os.getpid() % 100000}",
    )


def test_every_command_that_reads_a_file_reads_it_bounded() -> None:
    for path in _commands(main):
        for param in _command(path).params:
            assert not isinstance(param.type, click.File), f"{' '.join(path)} {param.name}"
            if isinstance(param.type, click.Path):
                assert (
                    not param.type.readable or param.type.writable or param.type.file_okay is False
                )


def test_the_commands_that_take_text_are_enumerated() -> None:
    names = {" ".join(path) for path in COMMANDS}
    assert {"team create", "user ssh-key add", "schedule import", "world update"} <= names


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("path", COMMANDS, ids=" ".join)
def test_bad_text_and_files_get_one_error_line(
    path: tuple[str, ...], mode: str, run: Callable[..., Result], files: dict[str, str]
) -> None:
    command = _command(path)
    inputs = _inputs(command)
    if mode != "not-utf8" and not any(isinstance(p.type, TextFile) for p in inputs):
        pytest.skip("no file to give")
    args = list(path)
    for param in command.params:
        if param in inputs:
            value = files[mode] if isinstance(param.type, TextFile) else NOT_UTF8
        elif isinstance(param.type, click.Choice):
            value = str(param.type.choices[0])
        elif param.required:
            value = "1"
        else:
            continue
        if isinstance(param, click.Option):
            args += [param.opts[0], value]
        else:
            args.append(value)
    result = run(*args)
    assert result.exit_code != 0, result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), result.exc_info
    errors = [line for line in result.output.splitlines() if line.startswith("Error")]
    assert len(errors) == 1 and "Traceback" not in result.output, result.output


def _cloudsim(env: dict[str, str], *args: str | bytes) -> subprocess.CompletedProcess[bytes]:
    return subprocess.run(
        [str(Path(".venv/bin/cloudsim").resolve()), *args],
        capture_output=True,
        env={**os.environ, **env},
        timeout=300,  # a hang fails; a loaded machine's slow start does not
    )


def test_the_reported_commands_as_a_shell_runs_them(
    tmp_path: Path, redis_server: RedisServer, encryption_key: str, files: dict[str, str]
) -> None:
    env = {
        "CLOUDSIM_INSTANCE_DIR": str(tmp_path / "instance"),
        "CLOUDSIM_REDIS_URL": redis_server.url(0),
        "CLOUDSIM_ENCRYPTION_KEYS": encryption_key,
        "LC_ALL": "C.UTF-8",
        "CLOUDSIM_PORTAL_URL": "https://portal.example.org:8443/",
    }
    before = _cloudsim(env, "portal", "certificate", "--out", str(tmp_path / "cert"))
    assert before.returncode != 0 and b"Traceback" not in before.stderr
    assert b"cloudsim db upgrade" in before.stderr, before.stderr
    assert _cloudsim(env, "db", "upgrade").returncode == 0
    for args in (
        ("team", "create", b"caf\xe9"),
        ("user", "ssh-key", "add", "a@example.org", files["not-utf8"]),
        ("schedule", "import", files["not-utf8"]),
        ("world", "update", "/dev/zero"),  # used to read forever
        ("world", "update", files["huge"]),
    ):
        done = _cloudsim(env, *args)
        lines = done.stderr.decode(errors="replace").splitlines()
        assert done.returncode != 0 and b"Traceback" not in done.stderr, done.stderr
        assert len([line for line in lines if line.startswith("Error")]) == 1, lines
