"""Verification's own VPN client: from the public side it connects to the router, checks the
kind's `vpn` reachability rows, is revoked, and must then be cut off.

Its certificate's serial is in the database (committed) before the key is written anywhere,
and the key lives only in a 0700 folder in the instance folder, removed after use; a check
that dies half-way is cleaned up (revoked, folder removed) by the next check of the
constellation (the resumed job) or by the sweeper (docs/metering.md).
"""

from __future__ import annotations

import os
import secrets
import shutil
import subprocess
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

from flask import current_app

from cloudsim.errors import CloudSimError
from cloudsim.jobs.runner import JobContext
from cloudsim.launched_constellations import vpn
from cloudsim.models import Constellation
from constellations.definition import VPN, Reachability
from constellations.plans.base import apply_plan
from constellations.plans.router import revocation
from provisioners.remote.ssh import SSHError, SSHExecutor, SSHTarget

# the provider's way to run argv on "the internet"; None: it has no such place
PublicCommand = Callable[[list[str]], list[str] | None]
There = Callable[[list[str]], list[str]]
CONNECT_SECONDS = 45
CUT_SECONDS = 20
PROBE_SECONDS = 3


def check_vpn(
    executor: SSHExecutor,
    constellation: Constellation,
    rows: list[Reachability],
    router: SSHTarget,
    public_command: PublicCommand,
    ctx: JobContext,
) -> list[dict[str, Any]]:
    """Return a result per `vpn` row (and one for the revocation), as verify stores them."""
    rows = [row for row in rows if row.source == VPN]
    if not rows:
        return []
    if public_command(["true"]) is None:
        ctx.log("VPN checks skipped: this provider offers no vantage point on the public side")
        return [check_result(row, None) for row in rows]

    def there(argv: list[str]) -> list[str]:
        return public_command(argv) or argv  # not None: the provider has a public side

    # an earlier attempt that died half-way: its client is cut off before a new one exists
    clean_up_checks(executor, constellation, router, ctx.checkpoint, ctx.log)
    name = f"cloudsim-verify-{secrets.token_hex(4)}"
    issued = vpn.issue_check_certificate(constellation, name)
    ctx.checkpoint()  # the serial is on record before the key is written or used
    config = vpn.client_config(constellation, name, issued.cert_pem, issued.key_pem)
    private = {m.name: m.private_ip or "" for m in constellation.machines}
    folder = _check_folder(constellation) / name
    folder.mkdir(mode=0o700, parents=True)
    try:
        path = folder / "check.ovpn"
        descriptor = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(descriptor, "w") as handle:
            handle.write(config)
        device = f"tunvc{secrets.token_hex(3)}"  # unique: other checks may run beside it
        # routes by device, not via the VPN's gateway address: another check's client (another
        # constellation, the same VPN network) may sit in the same namespace
        argv = ["openvpn", "--config", str(path), "--dev", device, "--route-noexec"]
        client = _Client(there(argv))
        try:
            if not client.wait_connected(CONNECT_SECONDS):
                ctx.log(f"VPN check client did not connect: {client.tail()}")
                return [check_result(row, False) for row in rows]
            route = ["ip", "route", "replace", constellation.resources["subnet"], "dev", device]
            subprocess.run(there(route), check=True, capture_output=True, timeout=30)
            # all at once: each closed row waits PROBE_SECONDS for its timeout
            with ThreadPoolExecutor(max_workers=len(rows)) as pool:
                opened = list(
                    pool.map(lambda row: _reaches(there, private[row.target], row.port), rows)
                )
            results = [check_result(row, seen) for row, seen in zip(rows, opened, strict=True)]
            # revoked, the check client must lose the LAN within seconds
            vpn.revoke_certificate(constellation, issued.serial, name)
            ctx.checkpoint()  # record the list before the router gets it (and let go of SQLite)
            apply_plan(executor, router, revocation(vpn.server_material(constellation)))
            open_row = next((r for r in rows if r.allowed), rows[0])
            deadline = time.monotonic() + CUT_SECONDS
            reached = True
            while reached and time.monotonic() < deadline:
                reached = _reaches(there, private[open_row.target], open_row.port)
            after = Reachability(VPN, open_row.target, open_row.port, allowed=False)
            return [*results, {**check_result(after, reached), "after": "revocation"}]
        finally:
            client.stop()
    finally:
        shutil.rmtree(folder, ignore_errors=True)
        try:  # a check that failed before its revocation must not leave its key valid
            clean_up_checks(executor, constellation, router, ctx.checkpoint, ctx.log)
        except (CloudSimError, SSHError) as exc:
            # still pending in the database: the next check or the sweeper revokes it
            ctx.log(f"could not revoke the VPN check certificate yet: {exc}")


def checks_root() -> Path:
    """Return the folder (in the instance folder, 0700) that holds check clients' keys."""
    root = Path(current_app.config["CLOUDSIM"].instance_dir) / "vpn-checks"
    root.mkdir(mode=0o700, parents=True, exist_ok=True)
    os.chmod(root, 0o700)
    return root


def _check_folder(constellation: Constellation) -> Path:
    folder = checks_root() / str(constellation.id)
    folder.mkdir(mode=0o700, exist_ok=True)
    return folder


def clean_up_checks(
    executor: SSHExecutor,
    constellation: Constellation,
    router: SSHTarget,
    commit: Callable[[], None],
    log: Callable[[str], None],
) -> list[int]:
    """Revoke the constellation's check certificates still pending, push the list to its
    router, and remove what their clients left on disk; return the revoked serials.

    `commit` is the caller's (the job's checkpoint, the sweeper's commit): the revocation is
    on record before the router gets the list.
    """
    revoked = vpn.revoke_check_certificates(constellation)
    if revoked:
        commit()
        apply_plan(executor, router, revocation(vpn.server_material(constellation)))
        vpn.forget_check_certificates(constellation, revoked)
        commit()
        log(f"VPN check certificate(s) {revoked} revoked on the router")
    shutil.rmtree(checks_root() / str(constellation.id), ignore_errors=True)
    return revoked


def check_result(row: Reachability, connected: bool | None) -> dict[str, Any]:
    """Return a reachability row's result as verification stores it (None: not checked)."""
    return {
        "from": row.source,
        "to": row.target,
        "port": row.port,
        "expected": "open" if row.allowed else "closed",
        "seen": "not checked" if connected is None else ("open" if connected else "closed"),
        "ok": connected is None or connected == row.allowed,
    }


def _reaches(there: There, address: str, port: int) -> bool:
    """Return True when the public side, through the VPN, reaches address:port (refused counts:
    the firewalls drop what they deny)."""
    probe = f"exec 3<>/dev/tcp/{address}/{port}"
    argv = there(["timeout", str(PROBE_SECONDS), "bash", "-c", probe])
    result = subprocess.run(argv, capture_output=True, text=True, check=False, timeout=30)
    return result.returncode == 0 or "Connection refused" in result.stderr


class _Client:
    """A stock OpenVPN client process, its output read in a thread."""

    def __init__(self, argv: list[str]) -> None:
        self.process = subprocess.Popen(
            argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
        )
        self.lines: list[str] = []
        self.connected = threading.Event()
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self.lines.append(line.rstrip())
            if "Initialization Sequence Completed" in line:
                self.connected.set()

    def wait_connected(self, seconds: float) -> bool:
        return self.connected.wait(seconds)

    def tail(self) -> str:
        return " | ".join(self.lines[-5:])

    def stop(self) -> None:
        self.process.terminate()
        try:
            self.process.wait(10)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait(10)
        self.reader.join(5)
        if self.process.stdout is not None:
            self.process.stdout.close()
