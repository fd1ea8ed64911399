"""Directory, file and template operations, from data (fact in -> steps out)."""

from __future__ import annotations

import hashlib
import shlex
import subprocess
from pathlib import Path

import pytest

from provisioners.remote.facts import PathFact, PathState
from provisioners.remote.operations import (
    Command,
    MachineTemplates,
    OperationError,
    TemplateError,
    Upload,
    directory,
    file,
    template,
)

MOTD_CONTEXT = {"constellation": "vrc-7", "machine": "sim", "role": "simulator", "team": "7"}


def run_fact_locally(fact: PathFact) -> PathState:
    """Run a fact's command in a local shell (read-only) and parse it as apply() would."""
    done = subprocess.run(["sh", "-c", fact.command], capture_output=True, text=True, check=True)
    return fact.parse(done.stdout, done.returncode)


def test_directory_absent_is_created_with_mode_and_owner() -> None:
    operation = directory("/srv/cloudsim", mode=0o750, owner="cloudsim", group="adm")
    assert operation.steps(PathState.absent()) == [
        Command("mkdir -p -m 0750 /srv/cloudsim"),
        Command("chown cloudsim:adm /srv/cloudsim"),
    ]


def test_directory_already_right_needs_nothing() -> None:
    state = PathState("directory", 0o750, "cloudsim", "adm")
    assert directory("/srv/cloudsim", mode=0o750, owner="cloudsim", group="adm").steps(state) == []
    assert directory("/srv/cloudsim", mode=0o750).steps(state) == []


def test_directory_with_other_mode_or_owner_is_fixed() -> None:
    state = PathState("directory", 0o777, "root", "adm")
    assert directory("/srv/cloudsim", mode=0o750, owner="cloudsim", group="adm").steps(state) == [
        Command("chmod 0750 /srv/cloudsim"),
        Command("chown cloudsim /srv/cloudsim"),
    ]
    assert directory("/srv/cloudsim", mode=0o777, group="staff").steps(state) == [
        Command("chown :staff /srv/cloudsim")
    ]


def test_directory_refuses_to_replace_a_file() -> None:
    with pytest.raises(OperationError, match="is a file, not a directory"):
        directory("/srv/cloudsim").steps(PathState("file", 0o644, "root", "root"))


def test_paths_are_quoted_in_every_command() -> None:
    nasty = "/srv/it's a dir; rm -rf /"
    (mkdir,) = directory(nasty).steps(PathState.absent())
    assert isinstance(mkdir, Command)
    assert shlex.split(mkdir.text) == ["mkdir", "-p", "-m", "0755", nasty]
    with pytest.raises(ValueError, match="absolute"):
        directory("relative/path")


def test_file_absent_or_different_is_uploaded_whole() -> None:
    operation = file("/etc/motd", "hello\n", mode=0o640, owner="root", group="adm")
    expected = [Upload("/etc/motd", b"hello\n", mode=0o640, owner="root", group="adm")]
    assert operation.steps(PathState.absent()) == expected
    other = PathState("file", 0o640, "root", "adm", sha256=hashlib.sha256(b"old\n").hexdigest())
    assert operation.steps(other) == expected
    assert expected[0].sha256 == hashlib.sha256(b"hello\n").hexdigest()
    assert "hello" not in expected[0].describe()


def test_file_with_same_checksum_is_not_uploaded() -> None:
    digest = hashlib.sha256(b"hello\n").hexdigest()
    operation = file("/etc/motd", "hello\n", mode=0o644)
    assert operation.steps(PathState("file", 0o644, "root", "root", sha256=digest)) == []
    assert operation.steps(PathState("file", 0o600, "root", "root", sha256=digest)) == [
        Command("chmod 0644 /etc/motd")
    ]


def test_file_refuses_to_replace_a_directory() -> None:
    with pytest.raises(OperationError, match="is a directory, not a regular file"):
        file("/etc/motd", "x").steps(PathState("directory", 0o755, "root", "root"))


def test_path_fact_parses_each_kind() -> None:
    fact = PathFact("/etc/motd", checksum=True)
    assert fact.parse("absent\n", 0) == PathState.absent()
    digest = "ab" * 32
    assert fact.parse(f"file 644 root adm\n{digest}  /etc/motd\n", 0) == PathState(
        "file", 0o644, "root", "adm", digest
    )
    assert fact.parse("directory 2775 root staff\n", 0) == PathState(
        "directory", 0o2775, "root", "staff"
    )
    with pytest.raises(ValueError):
        fact.parse("socket 644 root root\n", 0)


def test_path_fact_command_reads_a_real_tree(tmp_path: Path) -> None:
    weird = tmp_path / "it's a file"
    weird.write_bytes(b"content\n")
    weird.chmod(0o640)
    (tmp_path / "link").symlink_to(weird)
    assert run_fact_locally(PathFact(str(weird), checksum=True)) == PathState(
        "file", 0o640, "root", "root", hashlib.sha256(b"content\n").hexdigest()
    )
    assert run_fact_locally(PathFact(str(tmp_path / "link"))).kind == "link"
    assert run_fact_locally(PathFact(str(tmp_path))).kind == "directory"
    assert run_fact_locally(PathFact(str(tmp_path / "missing"))) == PathState.absent()


def test_template_renders_the_machine_template() -> None:
    operation = template("/etc/motd", "common/motd.j2", MOTD_CONTEXT)
    (upload,) = operation.steps(PathState.absent())
    assert isinstance(upload, Upload)
    assert upload.content.decode().splitlines() == [
        "CloudSim constellation vrc-7: machine sim (simulator)",
        "Team: 7",
        "Managed by CloudSim; local changes may be overwritten.",
    ]
    assert operation.name == "template common/motd.j2 -> /etc/motd"


def test_undefined_template_variable_names_file_and_line() -> None:
    context = {key: value for key, value in MOTD_CONTEXT.items() if key != "role"}
    with pytest.raises(TemplateError) as error:
        template("/etc/motd", "common/motd.j2", context)
    assert error.value.template.endswith("templates/machines/common/motd.j2")
    assert error.value.line == 2
    assert "'role' is undefined" in str(error.value)
    assert "common/motd.j2, line 2" in str(error.value)


def test_template_errors_in_syntax_includes_and_missing_files(tmp_path: Path) -> None:
    (tmp_path / "broken.j2").write_text("ok\nok\n{% if %}\n")
    (tmp_path / "part.j2").write_text("first\n{{ 1 / nothing }}\n")
    (tmp_path / "outer.j2").write_text("{% include 'part.j2' %}\n")
    templates = MachineTemplates(tmp_path)
    with pytest.raises(TemplateError) as syntax:
        templates.render("broken.j2", {})
    assert (syntax.value.template, syntax.value.line) == (str(tmp_path / "broken.j2"), 3)
    with pytest.raises(TemplateError) as included:
        templates.render("outer.j2", {})
    assert (included.value.template, included.value.line) == (str(tmp_path / "part.j2"), 2)
    with pytest.raises(TemplateError, match="not found"):
        templates.render("absent.j2", {})
