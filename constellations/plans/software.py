"""Software for machines without internet: a wheelhouse built here, uploaded, installed offline."""

from __future__ import annotations

import fcntl
import hashlib
import json
import shlex
import shutil
import subprocess
import tarfile
import tempfile
import tomllib
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path
from urllib.parse import urlsplit
from urllib.request import url2pathname

from constellations.plans.base import Action
from provisioners.remote.ssh import SSHExecutor, SSHTarget

SUMS = "SHA256SUMS"
SOURCE_TARBALL = "cloudsim-source.tar.gz"
EDITABLES = "EDITABLES"  # the bundle's distributions installed from its source, one folder a line
REMOTE_ROOT = "/opt/cloudsim/wheelhouse"
WHEELHOUSE_SECONDS = 900  # pip wheel of a distribution and its dependencies, cached after
_SKIP = {"__pycache__", ".egg-info", "build", "dist", ".pytest_cache"}


class WheelhouseError(Exception):
    """The wheelhouse could not be built."""


def distribution_source(name: str) -> Path:
    """Return the source folder an installed distribution came from (pip's direct_url.json).

    Wheels for the machines are built from it; `make install` installs CloudSim, drcsim and
    cloudsim-router from this checkout, so each has one.
    """
    # A source folder's own *.egg-info (from a build there) may come first on sys.path.
    found = list(metadata.distributions(name=name))
    if not found:
        raise WheelhouseError(f"{name} is not installed")
    recorded = next(
        (d.read_text("direct_url.json") for d in found if d.read_text("direct_url.json")), "{}"
    )
    url = urlsplit(str(json.loads(recorded or "{}").get("url", "")))
    folder = Path(url2pathname(url.path))
    if url.scheme != "file" or not folder.is_dir():
        raise WheelhouseError(
            f"{name} was not installed from a source folder, so its wheels cannot be built "
            "for the machines (install it with `pip install -e FOLDER` or `pip install FOLDER`)"
        )
    return folder


def _source_digest(source: Path) -> str:
    digest = hashlib.sha256()
    for path in sorted(source.rglob("*")):
        if path.is_file() and not any(
            part in _SKIP or part.endswith(".egg-info") for part in path.relative_to(source).parts
        ):
            digest.update(str(path.relative_to(source)).encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def build_wheelhouse(source: Path, cache_dir: Path, python: str) -> Path:
    """Return a folder of wheels for the distribution in `source` and all its dependencies.

    `python` is an interpreter like the machines' (wheels and environment markers depend on
    its version). Built once per version of the source and cached; a half-built folder is
    never used.
    """
    target = cache_dir / f"{source.name}-{_source_digest(source)}"
    if (target / SUMS).is_file():
        return target
    cache_dir.mkdir(parents=True, exist_ok=True)
    with _building(cache_dir, source.name):
        if (target / SUMS).is_file():  # built by whoever held the lock before us
            return target
        with tempfile.TemporaryDirectory(dir=cache_dir, prefix=".building-") as scratch:
            # setuptools builds inside the folder it is given: build a copy, so launches in
            # other instances never share a build/ folder and the checkout stays clean
            copy = Path(scratch) / "source" / source.name
            shutil.copytree(source, copy, ignore=shutil.ignore_patterns(*_SKIP, "*.egg-info"))
            wheels = Path(scratch) / "wheels"
            argv = [python, "-m", "pip", "wheel", "--quiet", "--wheel-dir", str(wheels), str(copy)]
            try:
                result = subprocess.run(
                    argv, capture_output=True, text=True, check=False, timeout=WHEELHOUSE_SECONDS
                )
            except subprocess.TimeoutExpired as exc:
                raise WheelhouseError(
                    f"pip wheel {source} did not finish in {WHEELHOUSE_SECONDS} s"
                ) from exc
            if result.returncode != 0:
                raise WheelhouseError(f"pip wheel {source} failed: {result.stderr.strip()[-2000:]}")
            sums = "".join(
                f"{_file_sha256(wheel)}  {wheel.name}\n" for wheel in sorted(wheels.glob("*.whl"))
            )
            (wheels / SUMS).write_text(sums)
            shutil.rmtree(target, ignore_errors=True)
            wheels.rename(target)
    return target


@contextmanager
def _building(cache_dir: Path, name: str) -> Iterator[None]:
    """Hold a lock per wheelhouse name, so that launches at once build it only once."""
    with open(cache_dir / f".{name}.lock", "a") as lock_file:
        fcntl.flock(lock_file, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(lock_file, fcntl.LOCK_UN)


def _file_sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as handle:
        for chunk in iter(lambda: handle.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def _sums(text: str) -> dict[str, str]:
    pairs = (line.split() for line in text.splitlines() if line.strip())
    return {name: digest for digest, name in pairs}


def _offline_install(
    folder: Path, venv: str, description: str, install: str, only: set[str] | None = None
) -> Action:
    """Upload the files of `folder` the machine lacks, then run `install` once (marked in venv).

    In `install`, {remote} is the folder's path on the machine. `only` limits the upload to
    the wheels of these distributions.
    """
    remote = f"{REMOTE_ROOT}/{folder.name}"
    marker = _marker(venv, folder)
    wanted = {
        name: digest
        for name, digest in _sums((folder / SUMS).read_text()).items()
        if only is None or _distribution(name) in only
    }

    def run(executor: SSHExecutor, target: SSHTarget) -> bool:
        if executor.run(target, f"test -e {shlex.quote(marker)}", check=False).ok:
            return False
        executor.run(target, f"mkdir -p {shlex.quote(remote)}")
        listing = executor.run(target, f"cd {shlex.quote(remote)} && sha256sum -- * || true")
        present = _sums(listing.stdout)
        for name, digest in sorted(wanted.items()):
            if present.get(name) != digest:
                executor.put_file(target, folder / name, f"{remote}/{name}")
        command = install.format(remote=shlex.quote(remote))
        executor.run(target, f"{command} && touch {shlex.quote(marker)}", timeout=900)
        return True

    return Action(description, run)


def _marker(venv: str, folder: Path) -> str:
    """Return the file whose presence says folder's software is installed into venv."""
    return f"{venv}/.cloudsim-installed-{folder.name}"


def preinstall_command(wheelhouse: Path, venv: str, requirement: str) -> str:
    """Return a command installing requirement into venv from the wheelhouse where it lies
    (e.g. into an image every machine starts from), marked as install_wheelhouse marks it,
    so that action finds it done (also its `only` variant: a subset of the same wheels)."""
    q_wheelhouse = shlex.quote(str(wheelhouse))
    return (
        f"{_pip_into(venv)} --no-index --find-links {q_wheelhouse} {shlex.quote(requirement)} "
        f"&& touch {shlex.quote(_marker(venv, wheelhouse))}"
    )


def _pip_into(venv: str) -> str:
    """Return the start of a command that makes venv and installs into it with the system pip.

    A venv without its own pip, filled by the machine's pip without byte-compiling: ~4x less
    CPU than `python3 -m venv` (which installs pip) plus the venv's pip (3.3 s -> 0.7 s for
    csrouter, 7.0 s -> 2.8 s for the simulator), and provisioning is CPU-bound.
    """
    q_venv = shlex.quote(venv)
    return (
        f"python3 -m venv --without-pip {q_venv} && "
        f"python3 -m pip --python {q_venv}/bin/python install --quiet --no-compile"
    )


def _distribution(wheel: str) -> str:
    """Return the normalised distribution name of a wheel file name."""
    return wheel.split("-", 1)[0].lower().replace("_", "-")


def install_wheelhouse(
    wheelhouse: Path, venv: str, requirement: str, *, only: Sequence[str] = ()
) -> Action:
    """Upload the wheels the machine lacks and install `requirement` into `venv`, offline.

    With `only`, just those distributions are uploaded and installed, without their
    dependencies (e.g. a client library that needs few of the package's dependencies).
    """
    packages = " ".join(shlex.quote(p) for p in (only or [requirement]))
    no_deps = " --no-deps" if only else ""
    return _offline_install(
        wheelhouse,
        venv,
        f"install {requirement} from {wheelhouse.name} into {venv}",
        f"{_pip_into(venv)} --no-index{no_deps} --find-links {{remote}} {packages}",
        only={p.lower() for p in only} or None,
    )


def build_source_bundle(
    root: Path, cache_dir: Path, python: str, members: Sequence[Path] = ()
) -> Path:
    """Return a folder with a tarball of CloudSim's tracked source files and a wheelhouse of
    everything it needs to run (plus the build tools for an offline editable install).

    `members` are distributions CloudSim needs whose sources lie inside root (the simulator,
    the router): they are installed from the source too, editable, like CloudSim.
    """
    editables = [".", *(str(member.relative_to(root)) for member in members)]
    files = subprocess.run(
        ["git", "-C", str(root), "ls-files", "-z"], capture_output=True, check=False
    )
    if files.returncode != 0:
        raise WheelhouseError(f"{root} is not a git checkout: cannot bundle CloudSim's source")
    names = sorted(name for name in files.stdout.decode().split("\0") if name)
    digest = hashlib.sha256("\n".join(editables).encode())
    for name in names:
        path = root / name
        if path.is_file():
            digest.update(name.encode())
            digest.update(path.read_bytes())
    target = cache_dir / f"cloudsim-{digest.hexdigest()[:16]}"
    if (target / SUMS).is_file():
        return target
    cache_dir.mkdir(parents=True, exist_ok=True)
    with _building(cache_dir, "cloudsim"):
        if (target / SUMS).is_file():  # built by whoever held the lock before us
            return target
        with tempfile.TemporaryDirectory(dir=cache_dir, prefix=".building-") as scratch:
            bundle, source = Path(scratch) / "bundle", Path(scratch) / "source"
            bundle.mkdir()
            with tarfile.open(bundle / SOURCE_TARBALL, "w:gz") as tar:
                for name in names:
                    if (root / name).is_file():
                        tar.add(root / name, arcname=name)
            # the wheels are built from the tracked files, not in the checkout (see above)
            with tarfile.open(bundle / SOURCE_TARBALL) as tar:
                tar.extractall(source, filter="data")
            for argv in (
                ["wheel", "--wheel-dir", str(bundle), *(str(source / f) for f in editables)],
                ["download", "--no-deps", "--dest", str(bundle), "setuptools>=68", "wheel"],
            ):
                result = subprocess.run(
                    [python, "-m", "pip", *argv, "--quiet"],
                    capture_output=True,
                    text=True,
                    check=False,
                )
                if result.returncode != 0:
                    raise WheelhouseError(f"pip {argv[0]} failed: {result.stderr.strip()[-2000:]}")
            built = {_distribution(wheel.name): wheel for wheel in bundle.glob("*.whl")}
            for folder in editables:
                # installed from the source, in editable mode: their own wheels are not needed
                built[_project_name(source / folder)].unlink()
            (bundle / EDITABLES).write_text("".join(f"{folder}\n" for folder in editables))
            sums = "".join(f"{_file_sha256(p)}  {p.name}\n" for p in sorted(bundle.iterdir()))
            (bundle / SUMS).write_text(sums)
            shutil.rmtree(target, ignore_errors=True)
            bundle.rename(target)
    return target


def _project_name(source: Path) -> str:
    """Return the normalised distribution name declared in a source folder's pyproject.toml."""
    with (source / "pyproject.toml").open("rb") as handle:
        name = str(tomllib.load(handle)["project"]["name"])
    return name.lower().replace("_", "-")


def install_source_bundle(bundle: Path, root: str, venv: str) -> Action:
    """Upload CloudSim's source and wheels; unpack and install it (editable) into venv, offline."""
    q_root = shlex.quote(root)
    editables = " ".join(
        f"-e {shlex.quote(f'{root}/{folder}'.removesuffix('/.'))}"
        for folder in (bundle / EDITABLES).read_text().split()
    )
    return _offline_install(
        bundle,
        venv,
        f"install CloudSim from {bundle.name} into {venv}",
        f"rm -rf {q_root} && mkdir -p {q_root} && tar -xzf {{remote}}/{SOURCE_TARBALL} "
        f"-C {q_root} && {_pip_into(venv)} --no-index --find-links {{remote}} {editables}",
    )


def wait_for_port(port: int, seconds: int = 120) -> Action:
    """Wait until something on the machine listens on a TCP port (a service finished starting)."""
    probe = f"until (exec 3<>/dev/tcp/127.0.0.1/{port}) 2>/dev/null; do sleep 0.5; done"

    def run(executor: SSHExecutor, target: SSHTarget) -> bool:
        executor.run(
            target, f"timeout {seconds} bash -c {shlex.quote(probe)}", timeout=seconds + 30
        )
        return False

    return Action(f"wait for port {port}", run)
