"""A real OpenSSH server for tests: own config, host key and authorized_keys, on 127.0.0.1."""

from __future__ import annotations

import socket
import subprocess
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric import ed25519

SSHD = Path("/usr/sbin/sshd")
# sshd refuses to start without its privilege separation directory (compiled-in path)
PRIVSEP_DIR = Path("/run/sshd")
START_DEADLINE_SECONDS = 10.0


@dataclass(frozen=True)
class KeyPair:
    """An ed25519 key pair as the app would hand it over: private PEM text, public line."""

    private_pem: str
    public_line: str


def make_key_pair(private_format: serialization.PrivateFormat) -> KeyPair:
    """Generate an ed25519 key pair in memory."""
    key = ed25519.Ed25519PrivateKey.generate()
    private_pem = key.private_bytes(
        serialization.Encoding.PEM, private_format, serialization.NoEncryption()
    ).decode()
    public_line = (
        key.public_key()
        .public_bytes(serialization.Encoding.OpenSSH, serialization.PublicFormat.OpenSSH)
        .decode()
    )
    return KeyPair(private_pem=private_pem, public_line=public_line)


def free_port() -> int:
    """Return a TCP port on 127.0.0.1 that nothing listens on right now."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def wait_until(condition: Callable[[], bool], deadline_seconds: float, what: str) -> None:
    """Poll a condition until it holds, failing the test when the deadline passes."""
    deadline = time.monotonic() + deadline_seconds
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.02)


@dataclass
class SshServer:
    """One sshd process, started and stopped by its recorded PID."""

    workdir: Path
    port: int
    client_public_line: str
    host_key: KeyPair = field(
        default_factory=lambda: make_key_pair(serialization.PrivateFormat.OpenSSH)
    )
    process: subprocess.Popen[bytes] | None = None

    @property
    def host_key_line(self) -> str:
        """Return the host key as the store records it: "ssh-ed25519 BASE64"."""
        return " ".join(self.host_key.public_line.split()[:2])

    def start(self, wait: bool = True) -> None:
        """Write config and keys, start sshd -D and (optionally) wait until it listens."""
        self.workdir.mkdir(parents=True, exist_ok=True)
        host_key_path = self.workdir / "ssh_host_ed25519_key"
        host_key_path.write_text(self.host_key.private_pem)
        host_key_path.chmod(0o600)
        authorized = self.workdir / "authorized_keys"
        authorized.write_text(self.client_public_line + "\n")
        config = self.workdir / "sshd_config"
        config.write_text(
            "\n".join(
                [
                    f"Port {self.port}",
                    "ListenAddress 127.0.0.1",
                    f"HostKey {host_key_path}",
                    f"AuthorizedKeysFile {authorized}",
                    "PidFile none",
                    "UsePAM no",
                    "StrictModes no",
                    "PermitRootLogin prohibit-password",
                    "PasswordAuthentication no",
                    "KbdInteractiveAuthentication no",
                    "AllowTcpForwarding yes",
                    "MaxStartups 50",
                    "Subsystem sftp internal-sftp",
                    "",
                ]
            )
        )
        log = (self.workdir / "sshd.log").open("ab")
        with log:
            self.process = subprocess.Popen(
                [str(SSHD), "-D", "-e", "-f", str(config)],
                stdin=subprocess.DEVNULL,
                stdout=log,
                stderr=log,
            )
        if wait:
            self.wait_listening()

    def wait_listening(self) -> None:
        """Wait until sshd accepts TCP connections."""

        def listening() -> bool:
            assert self.process is not None
            if self.process.poll() is not None:
                log = (self.workdir / "sshd.log").read_text()
                raise AssertionError(f"sshd exited {self.process.returncode}: {log}")
            with socket.socket() as probe:
                return probe.connect_ex(("127.0.0.1", self.port)) == 0

        wait_until(listening, START_DEADLINE_SECONDS, f"sshd on port {self.port}")

    def stop(self) -> None:
        """Stop sshd by its PID and reap it."""
        if self.process is None:
            return
        if self.process.poll() is None:
            self.process.terminate()
            self.process.wait(timeout=10)
        self.process = None


@dataclass
class LogRecorder:
    """A log sink that keeps every (machine, line) it receives."""

    lines: list[tuple[str, str]] = field(default_factory=list)
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def __call__(self, machine_name: str, line: str) -> None:
        with self._lock:
            self.lines.append((machine_name, line))

    def text(self, machine_name: str | None = None) -> str:
        """Return the logged lines (of one machine, or all) joined by newlines."""
        with self._lock:
            return "\n".join(line for name, line in self.lines if machine_name in (None, name))
