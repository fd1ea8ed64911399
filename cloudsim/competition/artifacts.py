"""Run logs: copied off the machines (streamed, sha256-verified, resumable) into the log store.

Big logs travel over OpenSSH's client at wire speed, checked against the machine's pinned host
key, while the machine hashes its copy; small ones over the executor's open connection. The
store is a libcloud storage driver: `local` (a folder under the instance by default) or any
object store libcloud knows, so there is one code path for both.
"""

from __future__ import annotations

import errno
import hashlib
import os
import shlex
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from drcsim import rundir
from libcloud.storage.base import Container, StorageDriver
from libcloud.storage.drivers.local import LocalStorageDriver
from libcloud.storage.providers import get_driver
from libcloud.storage.types import ContainerDoesNotExistError, ObjectDoesNotExistError
from sqlalchemy import select

from cloudsim.config import Config
from cloudsim.errors import CloudSimError
from cloudsim.extensions import db
from cloudsim.models import Artifact, Run
from provisioners.remote.ssh import SSHError, SSHExecutor, SSHTarget
from provisioners.remote.ssh.openssh import OpenSSH

RUNS_DIR = "/var/lib/cloudsim/runs"
CHUNK = 1 << 20
# below this a log is copied over the connection already open: a new OpenSSH handshake
# (through the machine's proxy or jump) costs more than the bytes take
BULK_BYTES = 8 << 20


class LogCollectionError(CloudSimError):
    """A log could not be copied off a machine or did not arrive intact."""


@dataclass(frozen=True)
class RemoteLog:
    """A log of a run on one of its machines."""

    kind: str
    machine: str  # role in the constellation: sim or router
    filename: str
    required: bool = True


LOGIN_LOG_NAME = "logins-{machine}.tsv"


def run_dir(run_id: int) -> str:
    """Return the folder of a run's logs on the sim and the router."""
    return f"{RUNS_DIR}/{run_id}"


RUN_LOGS = (
    RemoteLog("score", "sim", rundir.SCORE),
    RemoteLog("final", "sim", rundir.FINAL, required=False),  # absent if the simulator died
    RemoteLog("meta", "sim", rundir.META),
    RemoteLog("commands", "sim", rundir.COMMANDS),
    RemoteLog("state", "sim", rundir.STATE),
    # the run's log for robotics tools; a simulator of an older release writes none
    RemoteLog("mcap", "sim", rundir.MCAP, required=False),
    RemoteLog("output", "sim", "simulator.log", required=False),
    RemoteLog("world", "sim", rundir.WORLD, required=False),  # the document it was built from
    RemoteLog("bandwidth", "router", "bandwidth.jsonl"),
    # who logged into each field computer (login_logs.py), by machine name
    *(
        RemoteLog("logins", fc, LOGIN_LOG_NAME.format(machine=fc), required=False)
        for fc in ("fc1", "fc2")
    ),
)


class LogStore:
    """Where run logs are kept: a libcloud storage container."""

    def __init__(self, config: Config) -> None:
        self.driver = _driver(config)
        self.container_name = config.artifact_container
        self._container: Container | None = None

    @property
    def container(self) -> Container:
        if self._container is None:
            try:
                self._container = self.driver.get_container(self.container_name)
            except ContainerDoesNotExistError:
                self._container = self.driver.create_container(self.container_name)
        return self._container

    @staticmethod
    def object_name(run_id: int, filename: str) -> str:
        """Return the name a run's log has in the store."""
        return f"runs/{run_id}/{filename}"

    def holds(self, name: str, size: int) -> bool:
        """Return whether the store has an object of that name and size."""
        try:
            return int(self.driver.get_object(self.container_name, name).size) == size
        except (ObjectDoesNotExistError, ContainerDoesNotExistError):
            return False

    def put(self, path: Path, name: str) -> None:
        """Store a local file under name (streamed from disk by the driver)."""
        self.driver.upload_object(str(path), self.container, name, verify_hash=False)

    def keep(self, path: Path, name: str) -> None:
        """Store a staged file and let go of it: moved into a local store on the same disk
        (no second copy of a big log), else uploaded and removed."""
        if isinstance(self.driver, LocalStorageDriver):
            folder = self.driver.get_container_cdn_url(self.container, check=True)
            target = Path(folder) / name
            target.parent.mkdir(parents=True, exist_ok=True)
            try:
                os.replace(path, target)
            except OSError as exc:
                if exc.errno != errno.EXDEV:
                    raise
            else:
                target.chmod(0o664)  # as the driver's own upload leaves it
                return
        self.put(path, name)
        path.unlink()

    def stream(self, name: str) -> Iterator[bytes]:
        """Yield the stored object in chunks."""
        obj = self.driver.get_object(self.container_name, name)
        yield from self.driver.download_object_as_stream(obj, chunk_size=CHUNK)

    def stream_from(self, name: str, offset: int) -> Iterator[bytes]:
        """Yield the stored object from byte `offset` on, in chunks (an upload resuming)."""
        obj = self.driver.get_object(self.container_name, name)
        if isinstance(self.driver, LocalStorageDriver):
            # libcloud's local range download reads the whole file into memory first
            with open(self.driver.get_object_cdn_url(obj), "rb") as handle:
                handle.seek(offset)
                while chunk := handle.read(CHUNK):
                    yield chunk
            return
        if offset >= int(obj.size):
            return
        yield from self.driver.download_object_range_as_stream(obj, offset, chunk_size=CHUNK)

    def lines(self, name: str) -> Iterator[str]:
        """Yield a stored text object line by line, without holding it whole in memory."""
        pending = b""
        for chunk in self.stream(name):
            pending += chunk
            *complete, pending = pending.split(b"\n")
            for line in complete:
                yield line.decode("utf-8", "replace")
        if pending:
            yield pending.decode("utf-8", "replace")


def _driver(config: Config) -> StorageDriver:
    if config.artifact_store == "local":
        config.artifact_dir.mkdir(parents=True, exist_ok=True)
        return get_driver("local")(str(config.artifact_dir))  # type: ignore[no-any-return]
    try:
        cls = get_driver(config.artifact_store)
    except AttributeError:
        raise CloudSimError(
            f"CLOUDSIM_ARTIFACT_STORE: libcloud has no storage provider {config.artifact_store!r}"
        ) from None
    options: dict[str, Any] = dict(config.artifact_options)
    return cls(config.artifact_key, config.artifact_secret, **options)  # type: ignore[no-any-return]


def file_sha256(path: Path) -> str:
    """Return a local file's SHA-256, read in chunks."""
    digest = hashlib.sha256()
    with path.open("rb") as handle:
        while chunk := handle.read(CHUNK):
            digest.update(chunk)
    return digest.hexdigest()


# Python's hashlib uses the CPU's SHA instructions (OpenSSL), coreutils' sha256sum does not:
# ~3x faster on a big log; sha256sum where the machine's Python is older than 3.11
_HASHER = (
    "python3 -c 'import hashlib, sys; "
    '[print(hashlib.file_digest(open(p, "rb"), "sha256").hexdigest(), p) for p in sys.argv[1:]]\' '
    '"$@" 2>/dev/null || sha256sum "$@"'
)
# the arguments that are regular files, as "$@"
_EXISTING = 'set --; for f in {paths}; do if test -f "$f"; then set -- "$@" "$f"; fi; done'


def remote_sha256s(executor: SSHExecutor, target: SSHTarget, paths: list[str]) -> dict[str, str]:
    """Return the SHA-256 of each of the files on a machine that is there, in one command."""
    existing = _EXISTING.format(paths=" ".join(shlex.quote(path) for path in paths))
    result = executor.run(target, f"{existing}; test $# -eq 0 || {{ {_HASHER}; }}", timeout=3600)
    pairs = (line.split(maxsplit=1) for line in result.stdout.splitlines() if line)
    return {path: checksum for checksum, path in pairs}


def remote_sha256(executor: SSHExecutor, target: SSHTarget, path: str) -> str | None:
    """Return the SHA-256 of a file on a machine, None when the file is not there."""
    return remote_sha256s(executor, target, [path]).get(path)


def remote_inventory(
    executor: SSHExecutor, target: SSHTarget, files: dict[str, int]
) -> tuple[dict[str, int], dict[str, str]]:
    """Return the size of each file (path: size to hash it at) that is on a machine, and the
    checksum of those smaller than BULK_BYTES or of the given size, in one command."""
    steps = ["set --"]
    for path, hash_at in files.items():
        quoted = shlex.quote(path)
        steps.append(
            f"if test -f {quoted}; then s=$(stat -c %s -- {quoted}); echo size $s {quoted}; "
            f'if test $s -lt {BULK_BYTES} -o $s -eq {hash_at}; then set -- "$@" {quoted}; fi; fi'
        )
    steps.append(f"test $# -eq 0 || {{ {_HASHER}; }}")
    result = executor.run(target, "; ".join(steps), timeout=3600)
    sizes: dict[str, int] = {}
    checksums: dict[str, str] = {}
    for line in result.stdout.splitlines():
        first, _, rest = line.partition(" ")
        if first == "size":
            size, _, path = rest.partition(" ")
            sizes[path] = int(size)
        elif rest:
            checksums[rest.strip()] = first
    return sizes, checksums


def collect_logs(
    run: Run,
    executor: SSHExecutor,
    reach: dict[str, SSHTarget],
    store: LogStore,
    staging: Path,
    log: Callable[[str], None],
    ran: bool = True,
) -> list[str]:
    """Copy each of the run's logs into the store unless it is there already with the same
    checksum; return the problems with logs that could not be copied (missing optional logs
    are no problem, nor any missing log of a run whose simulator never started)."""
    staging.mkdir(parents=True, exist_ok=True)
    problems: list[str] = []
    stored = {a.filename: a for a in run.artifacts}
    openssh = OpenSSH(executor.host_keys, log=executor.log)
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="bulk-copy") as bulk:
        for machine, target in reach.items():
            logs = [remote for remote in RUN_LOGS if remote.machine == machine]
            try:
                sources = _ask(run, executor, openssh, target, logs, stored)
            except SSHError as exc:
                for remote in logs:
                    problems.append(f"{remote.filename}: {exc}")
                    log(f"{remote.filename}: {exc}")
                continue
            for remote in logs:
                if remote.filename not in sources:
                    if remote.required and ran:
                        problems.append(f"{remote.filename}: not found on {remote.machine}")
                    log(f"{remote.filename}: not on {remote.machine}")
            # a big log starts copying at once; the small ones' round trips go meanwhile
            early = {
                filename: bulk.submit(_fetch, source, staging / filename)
                for filename, source in sources.items()
                if source.size >= BULK_BYTES
                and not _stored_already(store, run, stored.get(filename), source)
            }
            for filename in sorted(sources, key=lambda name: name in early):
                remote = next(r for r in logs if r.filename == filename)
                problem = _collect_one(
                    run, remote, stored, store, staging / filename, log,
                    sources[filename], early.get(filename),
                )  # fmt: skip
                if problem:
                    problems.append(problem)
    return problems


def _ask(
    run: Run,
    executor: SSHExecutor,
    openssh: OpenSSH,
    target: SSHTarget,
    logs: list[RemoteLog],
    stored: dict[str, Artifact],
) -> dict[str, _Source]:
    """Return where each of a machine's logs that is there lives, with its size and, for
    small logs and logs that may be stored already, its checksum: one command in all."""
    paths = {remote.filename: f"{run_dir(run.id)}/{remote.filename}" for remote in logs}
    hash_at = {path: _stored_size(stored, filename) for filename, path in paths.items()}
    sizes, checksums = remote_inventory(executor, target, hash_at)
    return {
        filename: _Source(executor, openssh, target, path, sizes[path], checksums.get(path))
        for filename, path in paths.items()
        if path in sizes
    }


@dataclass(frozen=True)
class _Source:
    """Where one log is and what its machine said of it."""

    executor: SSHExecutor
    openssh: OpenSSH
    target: SSHTarget
    path: str
    size: int
    checksum: str | None  # None: not asked yet (a big log is hashed while it is copied)


def _stored_size(stored: dict[str, Artifact], filename: str) -> int:
    artifact = stored.get(filename)
    return artifact.size if artifact is not None else -1  # -1: no size a file has


def _stored_already(store: LogStore, run: Run, artifact: Artifact | None, source: _Source) -> bool:
    return (
        artifact is not None
        and artifact.sha256 == source.checksum
        and store.holds(store.object_name(run.id, artifact.filename), source.size)
    )


def _collect_one(
    run: Run,
    remote: RemoteLog,
    stored: dict[str, Artifact],
    store: LogStore,
    local: Path,
    log: Callable[[str], None],
    source: _Source,
    fetching: Future[tuple[str, int]] | None,
) -> str | None:
    """Copy one log into the store unless it is there already; return the problem, if any."""
    name = store.object_name(run.id, remote.filename)
    artifact = stored.get(remote.filename)
    try:
        if fetching is None and _stored_already(store, run, artifact, source):
            assert artifact is not None
            log(f"{remote.filename}: stored already ({artifact.sha256[:12]})")
            return None
        checksum, size = fetching.result() if fetching is not None else _fetch(source, local)
        store.keep(local, name)
    except (SSHError, LogCollectionError, OSError) as exc:
        log(f"{remote.filename}: {exc}")
        return f"{remote.filename}: {exc}"
    if artifact is None:
        artifact = Artifact(filename=remote.filename, kind=remote.kind)
        run.artifacts.append(artifact)  # a second collection in this session sees it
    artifact.location = name
    artifact.sha256 = checksum
    artifact.size = size
    db.session.flush()
    log(f"{remote.filename}: {size} bytes, sha256 {checksum[:12]} verified and stored")
    return None


def _fetch(source: _Source, local: Path) -> tuple[str, int]:
    """Copy a log into local (unless a staged copy from a previous try is whole); return its
    checksum as the machine computed it, and its size, once the copy is known to match."""
    executor, target, path = source.executor, source.target, source.path
    checksum = source.checksum
    if local.exists():  # downloaded by a try that failed to store it
        checksum = checksum or remote_sha256(executor, target, path)
        if checksum is not None and file_sha256(local) == checksum:
            return checksum, local.stat().st_size
        local.unlink()
    if source.size < BULK_BYTES:
        checksum = checksum or remote_sha256(executor, target, path)
        transfer = executor.get_file(target, path, local)
    else:
        # the machine hashes its copy while the bytes flow; ours is hashed as they arrive
        with ThreadPoolExecutor(max_workers=1, thread_name_prefix="sha256") as hashing:
            remote = hashing.submit(remote_sha256, executor, target, path)
            transfer = source.openssh.download(target, path, local)
            checksum = remote.result()
    if checksum is None or transfer.sha256 != checksum:
        local.unlink(missing_ok=True)  # the next try starts over, the resumed part included
        raise LogCollectionError(
            f"checksum mismatch: {target.name} has {(checksum or 'no file')[:12]}, "
            f"received {transfer.sha256[:12]}"
        )
    return checksum, transfer.size


def artifact_for(run: Run, filename: str) -> Artifact | None:
    """Return the run's stored log of that name."""
    return db.session.scalar(
        select(Artifact).where(Artifact.run_id == run.id, Artifact.filename == filename)
    )
