"""Image layers: software installed once on this machine, seen read-only by every later host.

A host's root is an overlay of this machine's "/"; a layer is what a command changed in a
scratch overlay of "/" (e.g. a virtualenv with the simulator), kept on the hosts' tmpfs and
stacked above "/" for hosts created afterwards. Thirty simulators then share one copy of the
install (in memory and in the page cache) instead of each unpacking and installing their
own; a host's writes to it are copied up into its own upper dir, as for "/".
"""

import shutil
from pathlib import Path

from provisioners.providers.local.commands import run_command

LAYERS_DIR = ".layers"  # in the hosts' tmpfs; node names cannot start with "."
BUILD_PREFIX = ".build-"
LOWERDIR_FILE = "lowerdir"  # in a host's dir: its overlay's lower layers, fixed at creation
BUILD_SECONDS = 900.0

# Runs in a private mount namespace: the scratch overlay vanishes with it, its upper stays.
BUILD = r"""
set -euo pipefail
build=$1 command=$2
mount -t overlay layer-build -o "lowerdir=/,upperdir=$build/upper,workdir=$build/work" \
  "$build/root"
mount -t proc proc "$build/root/proc"
mount --rbind /dev "$build/root/dev"
# the environment of a command run over SSH in a host (sshd's PATH), not the controller's
env -i PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin HOME=/root \
  LANG=C.UTF-8 PYTHONDONTWRITEBYTECODE=1 chroot "$build/root" /bin/bash -c "$command"
"""


def build_layer(hosts_dir: Path, name: str, command: str) -> bool:
    """Make layer name from what command changes in a copy of "/"; False if it exists.

    The caller holds the store's lock (hosts are neither created nor the tmpfs unmounted
    meanwhile); a half-built layer is never used.
    """
    layers = hosts_dir / LAYERS_DIR
    target = layers / name
    if target.is_dir():
        return False
    build = layers / f"{BUILD_PREFIX}{name}"
    shutil.rmtree(build, ignore_errors=True)
    for part in ("upper", "work", "root"):
        (build / part).mkdir(parents=True)
    (build / "upper").chmod(0o755)  # the mode of "/" where the layer is stacked
    argv = ["unshare", "--mount", "--propagation", "private", "--"]
    run_command(
        [*argv, "bash", "-c", BUILD, "layer-build", str(build), command], timeout=BUILD_SECONDS
    )
    (build / "upper").rename(target)
    shutil.rmtree(build)
    return True


def image_layers(hosts_dir: Path) -> list[Path]:
    """Return the finished layers, newest first (the overlay's order: top first)."""
    layers = hosts_dir / LAYERS_DIR
    if not layers.is_dir():
        return []
    done = [p for p in layers.iterdir() if p.is_dir() and not p.name.startswith(BUILD_PREFIX)]
    return sorted(done, key=lambda p: p.stat().st_mtime_ns, reverse=True)


def only_layers(hosts_dir: Path) -> bool:
    """Say whether the hosts' tmpfs holds image layers and nothing else (no host's files)."""
    if not hosts_dir.is_mount():
        return False
    return all(entry.name == LAYERS_DIR for entry in hosts_dir.iterdir())


def record_lowerdir(host_dir: Path) -> None:
    """Fix the host's lower layers (the layers now, then "/") unless fixed at an earlier boot."""
    lowerdir = host_dir / LOWERDIR_FILE
    if not lowerdir.exists():
        layers = [str(layer) for layer in image_layers(host_dir.parent)]
        lowerdir.write_text(":".join([*layers, "/"]) + "\n")
