"""The verify stage: every machine answers, the reachability matrix holds, the simulator runs."""

from __future__ import annotations

import json
import shlex
import socket
import subprocess
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, TypeVar

from cloudsim.error_codes import LAUNCH_SIM_SLOW, LAUNCH_VERIFY_FAILED
from cloudsim.errors import CloudSimError
from cloudsim.jobs.runner import JobContext
from cloudsim.launched_constellations.vpn_check import PublicCommand, check_result, check_vpn
from cloudsim.models import Constellation, utcnow
from constellations.definition import PUBLIC, VPN, ConstellationKind, Reachability
from provisioners.remote.ssh import SSHExecutor, SSHTarget

PROBE_SECONDS = 3
# sensors on: the rendering path (camera, lidar) must work too, not only the physics
# (the RTF the competition needs is checked here, not by drcsim: the figure goes in the error)
SELFTEST = "/opt/drcsim/bin/drcsim selftest --seconds 2 --min-rtf 0 --json"

# the provider's way to reach ip:port from "the internet" (an argv), None: from here
PublicProbe = Callable[[str, int], list[str] | None]
T = TypeVar("T")


@dataclass
class Retry:
    """Retry failed checks with backoff, until a deadline the whole verification shares.

    Load alone (a busy machine, thirty launches at once) makes a port answer late or an SSH
    handshake time out: a check that fails is tried again, each retry logged, and only one
    still failing when the bounded time is up fails the verification.
    """

    seconds: float
    log: Callable[[str], None]
    check: Callable[[], None] = lambda: None  # raises when the job must stop
    first_wait: float = 1.0
    longest_wait: float = 10.0
    deadline: float | None = None  # starts at the first retry

    def until(self, name: str, attempt: Callable[[], tuple[bool, T]]) -> T:
        """Return attempt's value once it reports success, or its last one when time is up."""
        self.check()
        ok, value = attempt()
        tries, wait = 1, self.first_wait
        while not ok:
            self.check()
            now = time.monotonic()
            if self.deadline is None:
                self.deadline = now + self.seconds
            left = self.deadline - now
            if left <= 0:
                self.log(f"{name}: still failing after {tries} tries; giving up")
                return value
            pause = min(wait, left)
            self.log(f"{name}: failed (try {tries}), retrying in {pause:.0f} s ({left:.0f} s left)")
            time.sleep(pause)
            self.check()
            tries, wait = tries + 1, min(wait * 2, self.longest_wait)
            ok, value = attempt()
        if tries > 1:
            self.log(f"{name}: passed on try {tries}")
        return value


class VerificationFailed(CloudSimError):
    """A check of the verify stage failed; the message lists every failed check."""

    def __init__(self, message: str, code: str = LAUNCH_VERIFY_FAILED) -> None:
        super().__init__(message)
        self.code = code


def verify_constellation(
    ctx: JobContext,
    executor: SSHExecutor,
    constellation: Constellation,
    kind: ConstellationKind,
    reach: dict[str, SSHTarget],
    public_probe: PublicProbe,
    public_command: PublicCommand,
    retry_seconds: float,
    min_rtf: float = 0.0,
) -> None:
    """Run every check (retrying failed ones), store the results per machine, raise listing
    the failures."""
    results: dict[str, dict[str, Any]] = {m.name: {"checks": []} for m in constellation.machines}
    failures: list[str] = []
    retry = Retry(retry_seconds, ctx.log, ctx.check)

    def hostname(target: SSHTarget) -> str | Exception:
        try:
            return executor.run(target, "hostname", timeout=30).stdout.strip()
        except Exception as exc:
            return exc

    answers = executor.run_parallel(
        list(reach.values()),
        lambda t: retry.until(
            f"{t.name.rsplit('/', 1)[-1]} answers over SSH",
            lambda: (not isinstance(answer := hostname(t), Exception), answer),
        ),
        raise_on_error=False,
    )
    for target_name, answer in answers.items():
        name = target_name.rsplit("/", 1)[-1]
        ok = not isinstance(answer, Exception)
        results[name]["ssh"] = {"ok": ok, "detail": str(answer)}
        if not ok:
            failures.append(f"{name} does not answer over SSH: {answer}")
    addresses = {m.name: (m.public_ip or m.private_ip or "") for m in constellation.machines}
    private = {m.name: m.private_ip or "" for m in constellation.machines}

    def probe(check: Reachability) -> bool:
        def attempt() -> tuple[bool, bool]:
            if check.source == PUBLIC:
                seen = _probe_public(public_probe, addresses[check.target], check.port)
            else:
                seen = _probe_from(executor, reach[check.source], private[check.target], check.port)
            return seen == check.allowed, seen

        return retry.until(_name(check), attempt)

    checks = [check for check in kind.reachability if check.source != VPN]  # VPN: below
    simulators = [m.name for m in kind.machines if "simulator" in m.plan]
    routers = [m.name for m in kind.machines if "router" in m.plan]
    # The probes (a forbidden pair is a connection that must time out, PROBE_SECONDS each) and
    # the self-tests run in threads, all at once, while the VPN check (it writes the
    # database, which belongs to this thread) runs here.
    with ThreadPoolExecutor(max_workers=max(1, len(checks) + len(simulators))) as pool:
        probes = [pool.submit(probe, check) for check in checks]
        selftests = {
            name: pool.submit(
                retry.until,
                f"{name}: simulator self-test",
                selftest_attempt(executor, reach[name], min_rtf),
            )
            for name in simulators
        }
        vpn_seen: list[dict[str, Any]] = []
        if routers:
            vpn_rows = [c for c in kind.reachability if c.source == VPN]
            router = reach[routers[0]]

            def vpn_checks() -> tuple[bool, list[dict[str, Any]]]:
                seen = check_vpn(executor, constellation, vpn_rows, router, public_command, ctx)
                return all(row["ok"] is not False for row in seen), seen

            vpn_seen = retry.until("the VPN checks", vpn_checks)
        outcomes = [future.result() for future in probes]
        tested = {name: future.result() for name, future in selftests.items()}
    for check, connected in zip(checks, outcomes, strict=True):
        owner = check.target if check.source == PUBLIC else check.source
        results[owner]["checks"].append(check_result(check, connected))
        if connected != check.allowed:
            failures.append(_describe(check, connected))
    for seen in vpn_seen:
        results[seen["to"]]["checks"].append(seen)
        if not seen["ok"]:
            failures.append(
                f"vpn -> {seen['to']}:{seen['port']} {seen['seen']}, expected "
                f"{seen['expected']}"
                + (" after the check client was revoked" if seen.get("after") else "")
            )
    slow = False
    for name, selftest in tested.items():
        results[name]["simulator"] = selftest
        if not selftest["ok"]:
            slow = slow or bool(selftest.get("slow"))
            failures.append(selftest_failure(name, selftest))
    stamp = utcnow().isoformat()
    for row in constellation.machines:
        row.verification = {**results[row.name], "at": stamp}
    ctx.checkpoint()  # kept even when verification fails below
    passed = sum(c["ok"] for r in results.values() for c in r["checks"])
    total = sum(len(r["checks"]) for r in results.values())
    ctx.log(f"reachability: {passed} of {total} checks as expected")
    if failures:
        code = LAUNCH_SIM_SLOW if slow and len(failures) == 1 else LAUNCH_VERIFY_FAILED
        raise VerificationFailed("verification failed: " + "; ".join(failures), code)


def _name(check: Reachability) -> str:
    expected = "connects" if check.allowed else "is refused"
    return f"{check.source} -> {check.target}:{check.port} {expected}"


def _describe(check: Reachability, connected: bool) -> str:
    seen = "connected" if connected else "could not connect"
    return f"{check.source} -> {check.target}:{check.port} {seen}, expected the opposite"


def _probe_from(executor: SSHExecutor, source: SSHTarget, address: str, port: int) -> bool:
    """Return True when a TCP connection from a machine reaches address:port.

    A refused connection reached it (nothing listens there now, e.g. the simulator's API
    between runs); the firewalls drop what they deny, so that times out.
    """
    probe = f"exec 3<>/dev/tcp/{address}/{port}"
    command = f"timeout {PROBE_SECONDS} bash -c {shlex.quote(probe)}"
    result = executor.run(source, command, check=False, timeout=PROBE_SECONDS + 10)
    return result.ok or "Connection refused" in result.stderr


def _probe_public(public_probe: PublicProbe, address: str, port: int) -> bool:
    """Return True when "the internet" (the provider's public side, or here) reaches address."""
    argv = public_probe(address, port)
    if argv is None:
        try:
            with socket.create_connection((address, port), timeout=PROBE_SECONDS):
                return True
        except OSError:
            return False
    try:
        result = subprocess.run(
            argv,
            stdin=subprocess.DEVNULL,
            capture_output=True,
            timeout=PROBE_SECONDS,
            check=False,
        )
    except subprocess.TimeoutExpired:
        return False
    return result.returncode == 0


def selftest_failure(name: str, selftest: dict[str, Any]) -> str:
    """Say why a machine's simulator self-test failed, with the figure measured if too slow."""
    if selftest.get("slow"):
        return (
            f"{name}: the simulator ran at a real-time factor of {selftest['rtf']}, under the "
            f"{selftest['min_rtf']} the competition needs (CLOUDSIM_SIM_MIN_RTF): the machine "
            "is too small or too busy"
        )
    return f"{name}: simulator self-test failed: {selftest.get('detail', '')}"


def selftest_attempt(
    executor: SSHExecutor, target: SSHTarget, min_rtf: float, command: str = SELFTEST
) -> Callable[[], tuple[bool, dict[str, Any]]]:
    def attempt() -> tuple[bool, dict[str, Any]]:
        found = _selftest(executor, target, command)
        if found["ok"] and float(found.get("rtf") or 0.0) < min_rtf:
            found.update(ok=False, slow=True, min_rtf=min_rtf)  # retried: load may pass
        return bool(found["ok"]), found

    return attempt


def _selftest(executor: SSHExecutor, target: SSHTarget, command: str) -> dict[str, Any]:
    result = executor.run(target, command, check=False, timeout=300)
    lines = [line for line in result.stdout.splitlines() if line.startswith("{")]
    if not result.ok or not lines:
        return {"ok": False, "detail": (result.stderr or result.stdout).strip()[-500:]}
    report = json.loads(lines[-1])
    return {"ok": bool(report.get("ok")), "rtf": report.get("rtf"), "world": report.get("world")}
