"""Fixtures for the local provider: a test-only prefix and state_dir, SSH keys, SSH sessions."""

import io
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

import paramiko
import pytest
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey
from cryptography.hazmat.primitives.serialization import (
    Encoding,
    NoEncryption,
    PrivateFormat,
    PublicFormat,
)
from libcloud.compute.base import Node

from provisioners.providers.local.driver import LocalNodeDriver

from .local_support import IS_ROOT, HostShell, SshKey, destroy_everything, open_shell


@pytest.fixture
def scratch() -> Iterator[Path]:
    """Give a test an empty directory, removed afterwards (pytest's tmp_path keeps 3 runs)."""
    directory = Path(tempfile.mkdtemp(prefix="cloudsim-local-test-"))
    yield directory
    shutil.rmtree(directory)


@pytest.fixture(scope="session")
def ssh_key() -> SshKey:
    """Generate an ed25519 key pair for this test session."""
    secret = Ed25519PrivateKey.generate()
    private_text = secret.private_bytes(
        Encoding.PEM, PrivateFormat.OpenSSH, NoEncryption()
    ).decode()
    public_text = secret.public_key().public_bytes(Encoding.OpenSSH, PublicFormat.OpenSSH).decode()
    return SshKey(
        private=paramiko.Ed25519Key.from_private_key(io.StringIO(private_text)),
        public_line=f"{public_text} cloudsim-local-tests",
    )


@pytest.fixture(scope="session")
def host_prefix() -> str:
    """Return a prefix no other CloudSim instance or test run uses."""
    return f"cst{os.getpid()}"


@pytest.fixture(scope="session")
def state_dir(host_prefix: str) -> Iterator[Path]:
    """Give the session a private state_dir; afterwards destroy whatever the prefix still has."""
    if not IS_ROOT:
        pytest.skip("local hosts need root")
    directory = Path(tempfile.mkdtemp(prefix=f"{host_prefix}-state-"))
    yield directory
    leftovers = destroy_everything(directory, host_prefix)
    shutil.rmtree(directory)
    assert leftovers == [], f"the tests left these behind: {leftovers}"


@pytest.fixture(scope="session")
def controller_secret(state_dir: Path, host_prefix: str) -> Iterator[Path]:
    """Make a file that stands for the app's secrets: hosts must not be able to read it."""
    directory = Path(tempfile.mkdtemp(prefix=f"{host_prefix}-instance-", dir="/var/lib"))
    secret = directory / "encryption.key"
    secret.write_text("not for hosts\n")
    yield secret
    shutil.rmtree(directory)


@pytest.fixture(scope="session")
def make_driver(
    state_dir: Path, host_prefix: str, controller_secret: Path
) -> Callable[[], LocalNodeDriver]:
    """Return a factory of fresh drivers sharing the session's state_dir and prefix."""

    def build() -> LocalNodeDriver:
        return LocalNodeDriver(
            state_dir=str(state_dir),
            prefix=host_prefix,
            hidden_paths=[str(controller_secret.parent)],
        )

    return build


@pytest.fixture(scope="session")
def driver(make_driver: Callable[[], LocalNodeDriver]) -> LocalNodeDriver:
    """Return the session's driver."""
    return make_driver()


@pytest.fixture
def shells() -> Iterator[Callable[[Node, SshKey], HostShell]]:
    """Open SSH sessions to nodes and close them all when the test ends."""
    opened: list[HostShell] = []

    def open_and_track(node: Node, key: SshKey) -> HostShell:
        shell = open_shell(node, key)
        opened.append(shell)
        return shell

    yield open_and_track
    for shell in opened:
        shell.close()
