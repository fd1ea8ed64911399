"""Fixtures: a real sshd per test, a client key, an executor that records its log."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from cryptography.hazmat.primitives import serialization

from provisioners.remote.ssh import ConnectPolicy, HostKeys, SSHExecutor, SSHTarget

from .sshd_server import PRIVSEP_DIR, KeyPair, LogRecorder, SshServer, free_port, make_key_pair


@pytest.fixture(scope="session")
def privsep_dir() -> Iterator[Path]:
    """Make sure sshd's privilege separation directory exists; remove it if we made it."""
    created = not PRIVSEP_DIR.exists()
    if created:
        PRIVSEP_DIR.mkdir(mode=0o755)
    yield PRIVSEP_DIR
    if created:
        PRIVSEP_DIR.rmdir()


@pytest.fixture(scope="session")
def client_key() -> KeyPair:
    """Return the key the controller logs in with (PKCS#8 PEM, as the app stores it)."""
    return make_key_pair(serialization.PrivateFormat.PKCS8)


@pytest.fixture
def sshd_factory(
    tmp_path: Path, privsep_dir: Path, client_key: KeyPair
) -> Iterator[Callable[..., SshServer]]:
    """Create sshd servers (not yet started unless asked); stop every one at teardown."""
    servers: list[SshServer] = []

    def make(port: int | None = None, start: bool = True) -> SshServer:
        server = SshServer(
            workdir=tmp_path / f"sshd-{len(servers)}",
            port=port or free_port(),
            client_public_line=client_key.public_line,
        )
        servers.append(server)
        if start:
            server.start()
        return server

    yield make
    for server in servers:
        server.stop()


@pytest.fixture
def sshd(sshd_factory: Callable[..., SshServer]) -> SshServer:
    """Return one running sshd."""
    return sshd_factory()


@pytest.fixture
def log() -> LogRecorder:
    """Return a recording log sink."""
    return LogRecorder()


@pytest.fixture
def host_keys() -> HostKeys:
    """Return an empty host key store."""
    return HostKeys()


@pytest.fixture
def executor(host_keys: HostKeys, log: LogRecorder) -> Iterator[SSHExecutor]:
    """Return an executor that logs to `log`; its connections close before sshd stops."""
    with SSHExecutor(
        host_keys,
        log_sink=log,
        secrets=["s3cret-token-value"],
        connect_policy=ConnectPolicy(deadline=15.0, attempt_timeout=5.0, first_delay=0.05),
        default_timeout=30.0,
    ) as ssh:
        yield ssh


@pytest.fixture
def make_machine(client_key: KeyPair) -> Callable[..., SSHTarget]:
    """Build SSHTarget descriptions that log in as root with the test client key."""

    def make(server: SshServer, name: str = "sim", **overrides: object) -> SSHTarget:
        fields: dict[str, object] = {
            "name": name,
            "host": "127.0.0.1",
            "port": server.port,
            "user": "root",
            "private_key": client_key.private_pem,
        }
        fields.update(overrides)
        return SSHTarget(**fields)  # type: ignore[arg-type]

    return make
