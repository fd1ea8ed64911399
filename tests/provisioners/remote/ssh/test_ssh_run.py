"""Running commands over SSH against a real sshd."""

from __future__ import annotations

import os
import signal
import threading
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

import paramiko
import pytest

from provisioners.remote.ssh import (
    CommandFailed,
    CommandTimeout,
    ConnectError,
    ConnectionLost,
    ConnectPolicy,
    HostKeys,
    SSHError,
    SSHExecutor,
    SSHTarget,
)

from .sshd_server import LogRecorder, SshServer, free_port, wait_until


def test_run_returns_stdout_stderr_and_exit_code(
    executor: SSHExecutor, sshd: SshServer, make_machine: Callable[..., SSHTarget]
) -> None:
    machine = make_machine(sshd)
    result = executor.run(machine, "echo out; echo err >&2; exit 3", check=False)
    assert (result.stdout, result.stderr, result.exit_code) == ("out\n", "err\n", 3)
    assert result.duration > 0
    assert executor.run(machine, "id -un").stdout == "root\n"


def test_command_reading_stdin_gets_end_of_file(
    executor: SSHExecutor, sshd: SshServer, make_machine: Callable[..., SSHTarget]
) -> None:
    result = executor.run(make_machine(sshd), "cat; echo after-eof", timeout=20)
    assert result.stdout == "after-eof\n"


def test_nonzero_exit_raises_command_failed_with_the_result(
    executor: SSHExecutor, sshd: SshServer, make_machine: Callable[..., SSHTarget]
) -> None:
    with pytest.raises(CommandFailed) as failure:
        executor.run(make_machine(sshd), "echo doomed >&2; exit 7")
    assert failure.value.result.exit_code == 7
    assert failure.value.result.stderr == "doomed\n"
    assert "exited 7" in str(failure.value) and "doomed" in str(failure.value)


def test_command_failed_message_masks_secrets(
    executor: SSHExecutor, sshd: SshServer, make_machine: Callable[..., SSHTarget]
) -> None:
    with pytest.raises(CommandFailed) as failure:
        executor.run(make_machine(sshd), "echo token s3cret-token-value refused >&2; exit 1")
    assert "s3cret-token-value" not in str(failure.value)
    assert "token *** refused" in str(failure.value)


def test_sudo_runs_the_command_as_root(
    executor: SSHExecutor, sshd: SshServer, make_machine: Callable[..., SSHTarget]
) -> None:
    assert executor.run(make_machine(sshd), "id -u", sudo=True).stdout == "0\n"


def test_timeout_raises_and_kills_the_remote_process(
    executor: SSHExecutor, sshd: SshServer, make_machine: Callable[..., SSHTarget], tmp_path: Path
) -> None:
    machine = make_machine(sshd)
    pid_file = tmp_path / "sleeper.pid"
    with pytest.raises(CommandTimeout) as timeout:
        executor.run(machine, f"sh -c 'echo $$ > {pid_file}; exec sleep 60'", timeout=1)
    assert timeout.value.timeout == 1
    pid = int(pid_file.read_text())

    def sleeper_gone() -> bool:
        # killed and orphaned, it may linger as a zombie until PID 1 reaps it
        try:
            stat = Path(f"/proc/{pid}/stat").read_text()
        except FileNotFoundError:
            return True
        return stat.rsplit(")", 1)[1].split()[0] == "Z"

    wait_until(sleeper_gone, 15, f"timed-out remote process {pid} to be killed")


def test_connection_is_reused_across_commands(
    executor: SSHExecutor, sshd: SshServer, make_machine: Callable[..., SSHTarget]
) -> None:
    machine = make_machine(sshd)
    ports = {executor.run(machine, "echo $SSH_CLIENT").stdout.split()[1] for _ in range(3)}
    assert len(ports) == 1


def test_connect_retries_until_the_server_listens(
    sshd_factory: Callable[..., SshServer],
    make_machine: Callable[..., SSHTarget],
    host_keys: HostKeys,
    log: LogRecorder,
) -> None:
    server = sshd_factory(start=False)
    machine = make_machine(server, name="booting")
    first_failure = threading.Event()

    def sink(name: str, line: str) -> None:
        log(name, line)
        if "connect attempt 1 failed" in line:
            first_failure.set()

    def start_server_after_first_failure() -> None:
        if first_failure.wait(timeout=15):
            server.start(wait=False)

    starter = threading.Thread(target=start_server_after_first_failure)
    starter.start()
    policy = ConnectPolicy(deadline=20.0, attempt_timeout=5.0, first_delay=0.05, max_delay=0.5)
    try:
        with SSHExecutor(host_keys, log_sink=sink, connect_policy=policy) as ssh:
            assert ssh.run(machine, "echo booted").stdout == "booted\n"
    finally:
        starter.join()
    assert first_failure.is_set()
    assert "connected on attempt" in log.text("booting")


def test_connect_gives_up_at_the_deadline(
    host_keys: HostKeys, client_key: object, make_machine: Callable[..., SSHTarget]
) -> None:
    nowhere = SshServer(workdir=Path("/nonexistent"), port=free_port(), client_public_line="")
    machine = make_machine(nowhere, name="ghost")
    policy = ConnectPolicy(deadline=0.5, attempt_timeout=0.5, first_delay=0.05, max_delay=0.1)
    with SSHExecutor(host_keys, connect_policy=policy) as ssh, pytest.raises(ConnectError) as error:
        ssh.run(machine, "true")
    assert "'ghost'" in str(error.value) and "Unable to connect to port" in str(error.value)


def test_wrong_client_key_is_a_connect_error(
    executor: SSHExecutor, sshd: SshServer, make_machine: Callable[..., SSHTarget]
) -> None:
    from cryptography.hazmat.primitives import serialization

    from .sshd_server import make_key_pair

    stranger = make_key_pair(serialization.PrivateFormat.OpenSSH)
    machine = make_machine(sshd, private_key=stranger.private_pem)
    quick = ConnectPolicy(deadline=0.5, attempt_timeout=2.0, first_delay=0.1)
    with SSHExecutor(HostKeys(), connect_policy=quick) as ssh:
        with pytest.raises(ConnectError) as error:
            ssh.run(machine, "true")
    assert "AuthenticationException" in str(error.value)
    assert stranger.private_pem.splitlines()[1] not in str(error.value)


def test_log_gets_commands_and_output_with_secrets_masked(
    executor: SSHExecutor,
    sshd: SshServer,
    make_machine: Callable[..., SSHTarget],
    log: LogRecorder,
    client_key: object,
) -> None:
    machine = make_machine(sshd, name="fc1")
    marker = uuid.uuid4().hex
    executor.run(machine, f"echo {marker} s3cret-token-value; echo warn-{marker} >&2")
    logged = log.text("fc1")
    assert f"$ echo {marker} *** ;" in logged or f"$ echo {marker} ***;" in logged
    assert f"{marker} ***" in logged.splitlines()
    assert f"! warn-{marker}" in logged.splitlines()
    assert "-> exit 0" in logged
    assert "s3cret-token-value" not in log.text()
    for key_line in machine.private_key.splitlines()[1:-1]:
        assert key_line not in log.text()


def test_run_parallel_returns_every_machine_result(
    executor: SSHExecutor, sshd: SshServer, make_machine: Callable[..., SSHTarget]
) -> None:
    machines = [make_machine(sshd, name="fc1"), make_machine(sshd, name="fc2")]
    results = executor.run_parallel(
        machines, lambda machine: executor.run(machine, f"echo {machine.name}").stdout
    )
    assert results == {"fc1": "fc1\n", "fc2": "fc2\n"}


def test_run_parallel_group_error_carries_every_machine_outcome(
    executor: SSHExecutor, sshd: SshServer, make_machine: Callable[..., SSHTarget]
) -> None:
    from provisioners.remote.ssh import GroupError

    machines = [make_machine(sshd, name="good"), make_machine(sshd, name="bad")]

    def task(machine: SSHTarget) -> str:
        return executor.run(machine, "true" if machine.name == "good" else "exit 4").stdout

    with pytest.raises(GroupError) as group:
        executor.run_parallel(machines, task)
    assert group.value.successes == {"good": ""}
    assert isinstance(group.value.failures["bad"], CommandFailed)
    assert "bad" in str(group.value)
    outcomes = executor.run_parallel(machines, task, raise_on_error=False)
    assert outcomes["good"] == "" and isinstance(outcomes["bad"], CommandFailed)


def test_a_command_ending_before_its_input_is_closed_keeps_the_connection(
    executor: SSHExecutor,
    sshd: SshServer,
    make_machine: Callable[..., SSHTarget],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """No end-of-input sent after the channel's close: OpenSSH would drop the connection.

    paramiko sends an EOF asked by the caller outside the channel's lock, so its reader
    thread can close the channel of a command that already ended first. On a loaded machine
    that happened on a router carrying sim's and the field computers' channels, and all of
    them broke. Here every EOF the caller's thread sends waits for that close, as it can
    (a command reading its input would wait for good: test_command_reading_stdin_... covers
    those).
    """
    machine = make_machine(sshd)
    send = paramiko.Transport._send_user_message

    def eof_after_the_reader(transport: paramiko.Transport, data: Any) -> None:
        raw = data.asbytes()
        if (
            raw[:1] == paramiko.common.cMSG_CHANNEL_EOF
            and threading.current_thread() is not transport
        ):
            remote_id = int.from_bytes(raw[1:5], "big")
            channels = [c for c in transport._channels.values() if c.remote_chanid == remote_id]
            for channel in channels:
                wait_until(_closed(channel), 10, "the reader to close the channel")
        send(transport, data)

    monkeypatch.setattr(paramiko.Transport, "_send_user_message", eof_after_the_reader)
    for n in range(3):
        assert executor.run(machine, f"echo {n}").stdout == f"{n}\n"
    sshd_log = (sshd.workdir / "sshd.log").read_text()
    assert "nonexistent channel" not in sshd_log
    assert sshd_log.count("Accepted publickey") == 1, sshd_log[-2000:]


def test_a_connection_broken_while_a_command_runs_fails_it_at_once(
    executor: SSHExecutor,
    sshd: SshServer,
    make_machine: Callable[..., SSHTarget],
    log: LogRecorder,
    tmp_path: Path,
) -> None:
    """A command whose connection broke fails then, not at its timeout (it cannot finish)."""
    pid_file = tmp_path / "proxy.pid"
    proxy = f"echo $$ > {pid_file}; exec socat STDIO TCP:127.0.0.1:{sshd.port}"
    machine = make_machine(sshd, proxy_command=["sh", "-c", proxy])
    outcome: list[BaseException] = []

    def run() -> None:
        try:
            executor.run(machine, "echo started; sleep 3", timeout=60)
        except SSHError as exc:
            outcome.append(exc)

    runner = threading.Thread(target=run)
    runner.start()
    wait_until(lambda: "started" in log.text(machine.name).splitlines(), 20, "its output")
    os.kill(int(pid_file.read_text()), signal.SIGKILL)  # the way to the machine breaks
    runner.join(30)
    assert not runner.is_alive()
    assert [type(e) for e in outcome] == [ConnectionLost], outcome
    assert "connection lost while running: echo started; sleep 3" in str(outcome[0])


def _closed(channel: paramiko.Channel) -> Callable[[], bool]:
    return lambda: bool(channel.closed)
