"""Move bulk bytes with OpenSSH's own client: a machine's pinned host key, nothing of the user's.

paramiko encrypts in Python and tops out well below the wire on a big file; OpenSSH's `ssh`
does the same job in C (AES-GCM with AES-NI). Each call writes the machine's key and its
recorded host key into a private temporary folder (0700, files 0600), runs `ssh` with no
configuration file, no agent, strict host key checking against that file alone and the
machine's stored route (its proxy command, or its jump machine through `ssh -W`), and removes
the folder afterwards, whatever happened.
"""

from __future__ import annotations

import hashlib
import os
import re
import shlex
import shutil
import subprocess
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from provisioners.remote.ssh.errors import ConnectError, HostKeyMismatch, SSHError
from provisioners.remote.ssh.hostkeys import HostKeyStore, fingerprint
from provisioners.remote.ssh.result import Transfer
from provisioners.remote.ssh.target import SSHTarget, openssh_private_key

# fastest first where the CPU has AES-NI; chacha20 for machines without it
CIPHERS = "aes128-gcm@openssh.com,aes256-gcm@openssh.com,chacha20-poly1305@openssh.com"
# the signature algorithms a recorded host key type is checked with
_HOST_KEY_ALGORITHMS = {"ssh-rsa": "rsa-sha2-512,rsa-sha2-256"}
_CHUNK = 1 << 20  # bytes hashed at a time: memory stays at one chunk
_STDERR_TAIL = 4096  # bytes of ssh's error output kept for the message
_STOP_GRACE_SECONDS = 5.0
_FOLLOW_WAIT_SECONDS = 0.002  # how long the hasher waits when it has caught up with ssh


class OpenSSH:
    """Run OpenSSH's `ssh` against machines whose host keys are pinned in a host key store."""

    def __init__(
        self,
        host_keys: HostKeyStore,
        *,
        connect_timeout: float = 10.0,
        log: Callable[[str, str], None] | None = None,
        program: str = "ssh",
    ) -> None:
        self._host_keys = host_keys
        self._connect_timeout = connect_timeout
        self._log = log or (lambda machine_name, line: None)
        self._program = program

    @staticmethod
    def available(program: str = "ssh") -> bool:
        """Return whether OpenSSH's client is installed."""
        return shutil.which(program) is not None

    @contextmanager
    def command(self, machine: SSHTarget, remote_command: str) -> Iterator[list[str]]:
        """Yield the argv that runs remote_command on machine; its key files live meanwhile."""
        with self._session(machine, remote_command) as (argv, _):
            yield argv

    @contextmanager
    def _session(self, machine: SSHTarget, remote_command: str) -> Iterator[tuple[list[str], Path]]:
        # mkdtemp's folder is 0700; TemporaryDirectory removes it and the keys in any case
        with tempfile.TemporaryDirectory(prefix="cloudsim-ssh-") as folder:
            files = _Files(Path(folder))
            argv = self._argv(machine, files)
            yield [*argv, "--", machine.host, remote_command], files.errors

    def download(
        self,
        machine: SSHTarget,
        remote_path: str,
        local_path: Path,
        *,
        progress: Callable[[int], None] | None = None,
    ) -> Transfer:
        """Copy a remote file into local_path, continuing a partial copy left by a previous try.

        The partial copy is `.NAME.part` beside local_path; the SHA-256 covers the whole file
        (the partial's bytes are read once from disk, the rest hashed as it streams in). The
        caller compares it with the machine's own checksum: a partial that does not belong to
        the file shows there, and is removed by the caller.
        """
        partial = local_path.with_name(f".{local_path.name}.part")
        digest = hashlib.sha256()
        offset = _hash_into(digest, partial) if partial.exists() else 0
        quoted = shlex.quote(remote_path)
        # tail seeks to the offset: a resumed copy reads only what is missing
        remote = f"cat -- {quoted}" if offset == 0 else f"tail -c +{offset + 1} -- {quoted}"
        self._log(
            machine.name,
            f"get {remote_path} -> {local_path} with OpenSSH"
            + (f", resuming at byte {offset}" if offset else ""),
        )
        size = offset
        with self._session(machine, remote) as (argv, errors), partial.open("ab") as out:
            with errors.open("ab") as stderr:  # ssh's own messages (-E) and the command's
                # ssh writes straight into the file, as a plain pipe would; we hash the file
                # as it grows (from the page cache): no pipe between us, one copy less
                process = subprocess.Popen(
                    argv, stdin=subprocess.DEVNULL, stdout=out, stderr=stderr, env=_environment()
                )
            try:
                size = _follow(partial, offset, process, digest, progress)
                exit_code = process.wait()
            finally:
                _stop(process)
            if exit_code != 0:
                if size == 0:
                    partial.unlink()  # nothing copied: no partial copy to resume
                raise _failure(machine, self._host_keys, remote_path, exit_code, errors)
        os.replace(partial, local_path)
        self._log(machine.name, f"-> {size} bytes ({size - offset} transferred)")
        return Transfer(size=size, sha256=digest.hexdigest(), resumed_from=offset)

    def _argv(self, machine: SSHTarget, files: _Files) -> list[str]:
        recorded = self._host_keys.get(machine.name)
        if recorded is None:
            raise ConnectError(
                f"machine {machine.name!r}: no recorded host key to check OpenSSH against "
                "(reach it once with the SSH executor first)"
            )
        key_type = recorded.split()[0]
        alias = files.pin(machine.name, recorded)
        argv = [
            self._program,
            "-F", "/dev/null",  # no user or system configuration
            "-T", "-x", "-a",  # no terminal, no X11, no agent forwarding
            "-E", str(files.errors),
            "-p", str(machine.port),
            "-l", machine.user,
            "-i", str(files.key(machine.name, machine.private_key)),
            "-o", "IdentitiesOnly=yes",
            "-o", "IdentityAgent=none",
            "-o", "BatchMode=yes",
            "-o", "PasswordAuthentication=no",
            "-o", "KbdInteractiveAuthentication=no",
            "-o", "StrictHostKeyChecking=yes",
            "-o", f"UserKnownHostsFile={files.known_hosts}",
            "-o", "GlobalKnownHostsFile=/dev/null",
            "-o", f"HostKeyAlias={alias}",
            "-o", f"HostKeyAlgorithms={_HOST_KEY_ALGORITHMS.get(key_type, key_type)}",
            "-o", "CheckHostIP=no",
            "-o", "UpdateHostKeys=no",
            "-o", "ControlMaster=no",
            "-o", "ControlPath=none",
            "-o", "ClearAllForwardings=yes",
            "-o", f"Ciphers={CIPHERS}",
            "-o", "Compression=no",
            "-o", f"ConnectTimeout={max(1, round(self._connect_timeout))}",
            "-o", "ServerAliveInterval=15",
            "-o", "ServerAliveCountMax=4",
            "-o", "LogLevel=ERROR",
        ]  # fmt: skip
        if machine.proxy_command is not None:
            argv += ["-o", f"ProxyCommand={_proxy(machine.proxy_command)}"]
        elif machine.jump is not None:
            hop = self._argv(machine.jump, files)
            host = f"[{machine.host}]" if ":" in machine.host else machine.host
            forward = f"{host}:{machine.port}"
            hop += ["-W", forward, "--", machine.jump.host]
            argv += ["-o", f"ProxyCommand={_proxy(hop)}"]
        return argv


class _Files:
    """The private folder's files: keys, the pinned host keys, ssh's error output."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.known_hosts = folder / "known_hosts"
        self.errors = folder / "errors"
        self._keys: dict[str, Path] = {}
        self._aliases: dict[str, str] = {}
        _write_private(self.known_hosts, b"")
        _write_private(self.errors, b"")

    def key(self, machine_name: str, key_text: str) -> Path:
        """Return the file holding a private key (written 0600 once per distinct key)."""
        path = self._keys.get(key_text)
        if path is None:
            path = self.folder / f"key{len(self._keys)}"
            _write_private(path, openssh_private_key(machine_name, key_text))
            self._keys[key_text] = path
        return path

    def pin(self, machine_name: str, key_type_and_base64: str) -> str:
        """Record a machine's host key under an alias only this folder uses; return the alias."""
        alias = self._aliases.get(machine_name)
        if alias is None:
            alias = f"cloudsim-machine-{len(self._aliases)}"
            self._aliases[machine_name] = alias
            line = f"{alias} {' '.join(key_type_and_base64.split()[:2])}\n"
            with self.known_hosts.open("a") as handle:
                handle.write(line)
        return alias


def _write_private(path: Path, data: bytes) -> None:
    descriptor = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(descriptor, "wb") as handle:
        handle.write(data)


def _proxy(argv: list[str]) -> str:
    # ssh expands %h, %p, ... in a ProxyCommand: a literal % is written %%
    return shlex.join(argv).replace("%", "%%")


def _environment() -> dict[str, str]:
    # no agent, whatever the caller's environment says
    return {key: value for key, value in os.environ.items() if not key.startswith("SSH_")}


def _follow(
    path: Path,
    offset: int,
    process: subprocess.Popen[bytes],
    digest: hashlib._Hash,
    progress: Callable[[int], None] | None,
) -> int:
    """Hash a file from offset as a process appends to it, until the process has ended and
    the end is reached; return the file's size then."""
    buffer = bytearray(_CHUNK)
    view = memoryview(buffer)
    with path.open("rb", buffering=0) as source:
        source.seek(offset)
        size = offset
        while True:
            ended = process.poll() is not None  # before reading: no byte written after is lost
            count = source.readinto(buffer) or 0
            if count:
                digest.update(view[:count])
                size += count
                if progress is not None:
                    progress(size)
            elif ended:
                return size
            else:
                try:  # the writer is ahead of nothing: wait a little for more, or its end
                    process.wait(_FOLLOW_WAIT_SECONDS)
                except subprocess.TimeoutExpired:
                    pass


def _hash_into(digest: hashlib._Hash, path: Path) -> int:
    size = 0
    with path.open("rb") as handle:
        while chunk := handle.read(_CHUNK):
            digest.update(chunk)
            size += len(chunk)
    return size


def _stop(process: subprocess.Popen[bytes]) -> None:
    if process.poll() is None:
        process.terminate()
        try:
            process.wait(_STOP_GRACE_SECONDS)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
    if process.stdout is not None:
        process.stdout.close()


def _failure(
    machine: SSHTarget, host_keys: HostKeyStore, remote_path: str, exit_code: int, errors: Path
) -> SSHError:
    text = errors.read_bytes()[-_STDERR_TAIL:].decode("utf-8", "replace") if errors.exists() else ""
    if "Host key verification failed" in text or "IDENTIFICATION HAS CHANGED" in text:
        presented = re.search(r"SHA256:[A-Za-z0-9+/]+", text)
        recorded = host_keys.get(machine.name) or ""
        return HostKeyMismatch(
            machine.name,
            fingerprint(recorded) if recorded else "none",
            presented.group(0) if presented else "another key",
        )
    detail = " / ".join(text.strip().splitlines()[-3:])
    how = f"killed by signal {-exit_code}" if exit_code < 0 else f"exit {exit_code}"
    return SSHError(
        f"{machine.name}: download of {remote_path} with OpenSSH failed ({how})"
        + (f": {detail}" if detail else "")
    )
