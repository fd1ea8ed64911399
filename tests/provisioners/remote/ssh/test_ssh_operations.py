"""Operations applied for real over SSH, confined to the test's temporary directory."""

from __future__ import annotations

import hashlib
import re
from collections.abc import Callable
from pathlib import Path

import pytest

from provisioners.remote.operations import (
    Command,
    Deploy,
    DeployFailed,
    OperationError,
    apply,
    authorized_key,
    deb_packages,
    directory,
    file,
    plan_on,
    service,
    template,
)
from provisioners.remote.ssh import SSHExecutor, SSHTarget

from .sshd_server import KeyPair, LogRecorder, SshServer

MOTD_CONTEXT = {"constellation": "vrc-7", "machine": "sim", "role": "simulator"}


@pytest.fixture
def machine(sshd: SshServer, make_machine: Callable[..., SSHTarget]) -> SSHTarget:
    """Return the machine every test here provisions."""
    return make_machine(sshd, name="sim")


@pytest.fixture
def target(tmp_path: Path) -> Path:
    """Return an empty directory the operations may change."""
    path = tmp_path / "target"
    path.mkdir()
    return path


def test_file_is_uploaded_once_then_left_alone(
    executor: SSHExecutor, machine: SSHTarget, target: Path, log: LogRecorder
) -> None:
    path = target / "motd"
    operation = file(str(path), "welcome\n", mode=0o640)
    first = apply(executor, machine, operation)
    assert first.changed
    digest = hashlib.sha256(b"welcome\n").hexdigest()
    assert first.commands[0].startswith(f"upload 8 bytes sha256:{digest[:16]} to ")
    assert path.read_text() == "welcome\n" and path.stat().st_mode & 0o777 == 0o640

    second = apply(executor, machine, operation)
    assert (second.changed, second.commands) == (False, [])
    assert f"[file {path}] already in the desired state" in log.text("sim")

    path.chmod(0o666)
    third = apply(executor, machine, operation)
    assert third.commands == [f"chmod 0640 {path}"]
    assert path.stat().st_mode & 0o777 == 0o640
    assert [p.name for p in target.iterdir()] == ["motd"]  # no staging file left behind


def test_changed_content_replaces_the_file_with_owner_applied(
    executor: SSHExecutor, machine: SSHTarget, target: Path
) -> None:
    path = target / "it's config.conf"
    path.write_text("old\n")
    result = apply(executor, machine, file(str(path), b"new\n", owner="root", group="root"))
    assert result.changed and re.search(r"chown root:root .* && mv -f ", result.commands[1])
    assert path.read_text() == "new\n"


def test_template_is_rendered_and_uploaded_via_sudo_staging(
    executor: SSHExecutor, machine: SSHTarget, target: Path, log: LogRecorder
) -> None:
    path = target / "motd"
    operation = template(str(path), "common/motd.j2", MOTD_CONTEXT)
    result = apply(executor, machine, operation, sudo=True)
    assert result.changed
    assert path.read_text().startswith("CloudSim constellation vrc-7: machine sim (simulator)\n")
    staging = re.fullmatch(
        r"chown root:root (/tmp/\.cloudsim-upload-[0-9a-f]+) && mv -f \1 \S+", result.commands[1]
    )
    assert staging is not None and not Path(staging.group(1)).exists()
    assert "$ sudo chown root:root /tmp/.cloudsim-upload-" in log.text("sim")
    assert not apply(executor, machine, operation, sudo=True).changed


def test_directory_is_created_then_left_alone(
    executor: SSHExecutor, machine: SSHTarget, target: Path
) -> None:
    path = target / "srv" / "cloudsim"
    operation = directory(str(path), mode=0o750, owner="root")
    assert apply(executor, machine, operation).commands == [
        f"mkdir -p -m 0750 {path}",
        f"chown root {path}",
    ]
    assert path.is_dir() and path.stat().st_mode & 0o777 == 0o750
    assert not apply(executor, machine, operation).changed


def test_installed_package_is_a_no_op(executor: SSHExecutor, machine: SSHTarget) -> None:
    # hosts have no internet: packages come with the overlay root, so this must not run apt
    result = apply(executor, machine, deb_packages(["openssh-server", "socat"]))
    assert (result.changed, result.commands) == (False, [])


def test_authorized_key_is_added_once(
    executor: SSHExecutor, machine: SSHTarget, target: Path, client_key: KeyPair
) -> None:
    keys = target / "ssh" / "authorized_keys"
    operation = authorized_key("root", client_key.public_line, path=str(keys))
    assert apply(executor, machine, operation).changed
    assert keys.read_text() == client_key.public_line + "\n"
    assert keys.stat().st_mode & 0o777 == 0o600 and keys.parent.stat().st_mode & 0o777 == 0o700
    assert not apply(executor, machine, operation).changed


def test_service_plan_reads_facts_over_ssh_without_running_anything(
    executor: SSHExecutor, machine: SSHTarget
) -> None:
    # the controller has no systemd: the plan falls back to init scripts
    assert plan_on(executor, machine, service("cloudsim-no-such-service")) == [
        Command("update-rc.d cloudsim-no-such-service defaults"),
        Command("service cloudsim-no-such-service start"),
    ]


def test_deploy_applies_in_order_and_is_idempotent(
    executor: SSHExecutor, machine: SSHTarget, target: Path
) -> None:
    etc = target / "etc"
    deploy = Deploy(
        [
            directory(str(etc), mode=0o755),
            template(str(etc / "motd"), "common/motd.j2", MOTD_CONTEXT),
            file(str(etc / "cloudsim.conf"), "role = sim\n", mode=0o600),
        ]
    )
    first = deploy.apply(executor, machine)
    assert [result.changed for result in first] == [True, True, True]
    assert (etc / "cloudsim.conf").read_text() == "role = sim\n"
    assert [result.changed for result in deploy.apply(executor, machine)] == [False] * 3


def test_deploy_stops_at_the_first_failure_and_names_it(
    executor: SSHExecutor, machine: SSHTarget, target: Path
) -> None:
    blocker = target / "blocker"
    blocker.write_text("a file where a directory should be\n")
    deploy = Deploy(
        [
            file(str(target / "first"), "1\n"),
            directory(str(blocker)),
            file(str(target / "never"), "3\n"),
        ]
    )
    with pytest.raises(DeployFailed) as failure:
        deploy.apply(executor, machine)
    assert failure.value.index == 1 and failure.value.operation_name == f"directory {blocker}"
    assert f"operation 2 (directory {blocker}) failed" in str(failure.value)
    assert isinstance(failure.value.__cause__, OperationError)
    assert [result.name for result in failure.value.completed] == [f"file {target / 'first'}"]
    assert not (target / "never").exists()


def test_deploy_reports_a_failing_command(
    executor: SSHExecutor, machine: SSHTarget, target: Path
) -> None:
    deploy = Deploy([directory(str(target / "locked" / "inner"), owner="cloudsim-nobody")])
    with pytest.raises(DeployFailed, match=r"chown: invalid user: .cloudsim-nobody.") as failure:
        deploy.apply(executor, machine)
    assert failure.value.completed == []
