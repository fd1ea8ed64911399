"""Start processes, restart the ones that die, stop them all (in reverse order) on a signal."""

from __future__ import annotations

import signal
import socket
import subprocess
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import FrameType

RESTART_DELAYS = (1.0, 2.0, 5.0, 10.0, 30.0)
STOP_GRACE_SECONDS = 10.0


@dataclass
class Service:
    """One supervised process."""

    name: str
    argv: list[str]
    env: dict[str, str] | None = None
    ready: Callable[[], bool] | None = None
    process: subprocess.Popen[bytes] | None = None
    restarts: int = 0
    started_at: float = 0.0

    def start(self, log_dir: Path | None = None) -> None:
        """Start the process, its output appended to log_dir/NAME.log (else to ours)."""
        if log_dir is None:
            self.process = subprocess.Popen(self.argv, env=self.env)
        else:
            log_dir.mkdir(mode=0o700, parents=True, exist_ok=True)
            with (log_dir / f"{self.name}.log").open("ab") as out:
                self.process = subprocess.Popen(
                    self.argv, env=self.env, stdout=out, stderr=subprocess.STDOUT
                )
        self.started_at = time.monotonic()


@dataclass
class Supervisor:
    """Run services until interrupted; report and restart any that exits on its own."""

    log: Callable[[str], None]
    log_dir: Path | None = None  # where each service's output goes; None: this process's own
    services: list[Service] = field(default_factory=list)
    _stopping: bool = False

    def add(self, service: Service, timeout: float = 30.0) -> None:
        """Start a service and wait until it is ready (when it says how to tell)."""
        service.start(self.log_dir)
        self.services.append(service)
        if service.ready is None:
            return
        deadline = time.monotonic() + timeout
        see = f" (its output: {self.log_dir / service.name}.log)" if self.log_dir else ""
        while not service.ready():
            if service.process is not None and service.process.poll() is not None:
                code = service.process.returncode
                raise RuntimeError(f"{service.name} exited with code {code}{see}")
            if time.monotonic() > deadline:
                raise RuntimeError(f"{service.name} not ready after {timeout:.0f} s{see}")
            time.sleep(0.1)

    def run(self) -> None:
        """Block until SIGINT/SIGTERM, restarting crashed services with backoff."""

        def request_stop(signum: int, _frame: FrameType | None) -> None:
            self._stopping = True

        signal.signal(signal.SIGINT, request_stop)
        signal.signal(signal.SIGTERM, request_stop)
        while not self._stopping:
            for service in self.services:
                assert service.process is not None
                code = service.process.poll()
                if code is None or self._stopping:
                    continue
                if time.monotonic() - service.started_at > 60:
                    service.restarts = 0  # it ran fine for a while: forget old crashes
                delay = RESTART_DELAYS[min(service.restarts, len(RESTART_DELAYS) - 1)]
                self.log(
                    f"{service.name} exited with code {code}; restarting in {delay:.0f} s"
                    + (f" (its output: {self.log_dir / service.name}.log)" if self.log_dir else "")
                )
                time.sleep(delay)
                service.restarts += 1
                service.start(self.log_dir)
            time.sleep(0.5)
        self.stop()

    def stop(self) -> None:
        """Stop every service, newest first: SIGTERM, then SIGKILL after a grace period."""
        for service in reversed(self.services):
            process = service.process
            if process is None or process.poll() is not None:
                continue
            self.log(f"stopping {service.name}")
            process.terminate()
            try:
                process.wait(STOP_GRACE_SECONDS)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()


def port_open(host: str, port: int) -> Callable[[], bool]:
    """Return a readiness check that succeeds once host:port accepts TCP connections."""

    def check() -> bool:
        try:
            with socket.create_connection((host, port), timeout=0.5):
                return True
        except OSError:
            return False

    return check
