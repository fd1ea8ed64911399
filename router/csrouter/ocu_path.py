"""The OCU path's shared state: the armed run, the delay lines, the log, faults.

The packet loop and the control thread both use it; every method takes the lock.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable
from typing import Any, Protocol

from csrouter import __version__
from csrouter.bandwidth_log import BandwidthLog, utc_iso
from csrouter.config import RouterConfig
from csrouter.delay import DelayLine, Lateness, Verdictable
from csrouter.errors import RouterError, RulesError
from csrouter.packets import measure
from csrouter.rules import missing_rules
from csrouter.run import DIRECTIONS, Run, SavedState

log = logging.getLogger("csrouter")


class QueuedPacket(Verdictable, Protocol):
    """A packet from NFQUEUE: its first bytes and a verdict to give."""

    def get_payload(self) -> bytes: ...


class OcuPath:
    """Decide, delay and count OCU<->LAN packets for the armed run."""

    def __init__(
        self,
        config: RouterConfig,
        *,
        monotonic: Callable[[], float] = time.monotonic,
        wall: Callable[[], float] = time.time,
    ) -> None:
        self.config = config
        self.lock = threading.Lock()
        self._monotonic, self._wall = monotonic, wall
        self.lines = {direction: DelayLine() for direction in DIRECTIONS}
        self.log = BandwidthLog(config.bandwidth_log)
        self.started_at = wall()
        self.stopping = False
        self.dropped_while_stopping = 0
        self.last_run: dict[str, Any] | None = None
        self.faults: list[str] = []
        self.run = Run(latency_ms=config.default_latency_ms)
        self._resume(self._read_state())
        self._second = 1  # the next second of the run to log (it ends `_second` s after the arm)
        self._next_tick = self._first_tick()
        # from now on a crash, however early, shows as an unclean exit at the next start
        self._save(clean_exit=False)

    # -- packets (packet loop) -------------------------------------------------------------

    def on_packet(self, direction: str, packet: QueuedPacket) -> None:
        """Measure one packet; drop it (over the cap, or stopping) or hold it for the latency."""
        arrived = self._monotonic()
        with self.lock:
            if self.stopping:
                self.dropped_while_stopping += 1
                packet.drop()
                return
            meter = self.run.meters[direction]
            was_spent = meter.spent
            if not meter.admit(measure(packet.get_payload())):
                if not was_spent:
                    meter.spent_at = utc_iso(self._wall())
                packet.drop()
                return
            self.lines[direction].hold(packet, arrived + self.run.latency_ms / 1000)

    def service(self) -> float:
        """Release due packets and write due log lines; return seconds until the next duty."""
        with self.lock:
            now = self._monotonic()
            for line in self.lines.values():
                line.release_due(now)
            if self.run.armed and now >= self._next_tick:
                self._tick(now)
            deadlines = [self._next_tick] if self.run.armed else [now + 1.0]
            deadlines += [t for t in (ln.next_release() for ln in self.lines.values()) if t]
            return max(0.0, min(deadlines) - self._monotonic())

    def held(self) -> int:
        """Return how many packets are waiting in the delay lines."""
        with self.lock:
            return sum(len(line) for line in self.lines.values())

    # -- control (control thread) ------------------------------------------------------------

    def arm(
        self,
        latency_ms: int,
        uplink_bits: int | None,
        downlink_bits: int | None,
        run_id: str | None,
    ) -> dict[str, Any]:
        """Start a run: new latency and caps, counters at zero, a new bandwidth log.

        Arming the run that is armed already changes nothing (its counters, caps and log go
        on): an orchestrator that resumes a run's start after a crash must not reset them.
        """
        with self.lock:
            if self.run.armed and run_id is not None and self.run.run_id == run_id:
                log.info("run %s is armed already; its counters go on", run_id)
                return {**self.run.counters(self._wall()), "already_armed": True}
        run = Run.arm(
            latency_ms=latency_ms,
            uplink_bits=uplink_bits,
            downlink_bits=downlink_bits,
            run_id=run_id,
            now=self._wall(),
        )
        with self.lock:
            self.run, self.faults, self.last_run = run, [], None
            for line in self.lines.values():
                line.lateness = Lateness()
            self._second, self._next_tick = 1, self._monotonic() + 1.0
            self.log.restart()
            self.log.append([self._event("armed")])
            self._save(clean_exit=False)
            log.info(
                "armed run %s: %d ms, caps %s/%s bits",
                run_id,
                latency_ms,
                uplink_bits,
                downlink_bits,
            )
            return {**self.run.counters(self._wall()), "already_armed": False}

    def disarm(self) -> dict[str, Any]:
        """End the run: caps lifted, final counts logged and returned; latency stays."""
        with self.lock:
            final = self.run.counters(self._wall())
            if self.run.armed:
                self._tick(self._monotonic())
                self.log.append([{**self._event("disarmed"), "counters": final}])
                self.last_run = final
            self.run = Run(latency_ms=self.run.latency_ms)
            self._save(clean_exit=False)
            return final

    def counters(self) -> dict[str, Any]:
        """Return the armed run's counts (and the last run's, after a disarm)."""
        with self.lock:
            return {**self.run.counters(self._wall()), "last_run": self.last_run}

    def status(self) -> dict[str, Any]:
        """Return the daemon's health: run, held packets, rules in place, faults."""
        try:
            missing = missing_rules(self.config)
            rules_error = None
        except RulesError as exc:
            missing, rules_error = [], str(exc)
        with self.lock:
            faults = list(self.faults)
            if missing:
                faults.append(f"NFQUEUE rules missing (OCU traffic bypasses csrouter): {missing}")
            if rules_error:
                faults.append(f"cannot read the NFQUEUE rules: {rules_error}")
            return {
                "daemon": "running",
                "healthy": not faults,
                "faults": faults,
                "version": __version__,
                "pid": os.getpid(),
                "started_at": utc_iso(self.started_at),
                "delay_method": "nfqueue",
                "netem_available": netem_available(),
                "armed": self.run.armed,
                "run_id": self.run.run_id,
                "latency_ms": self.run.latency_ms,
                "caps_bits": {d: self.run.meters[d].cap_bits for d in DIRECTIONS},
                "spent": {d: self.run.meters[d].spent for d in DIRECTIONS},
                "spent_at": {d: self.run.meters[d].spent_at for d in DIRECTIONS},
                "held_packets": {d: len(self.lines[d]) for d in DIRECTIONS},
                # since the arm: how late csrouter released packets (its own timing error)
                "release_lateness": {d: self.lines[d].lateness.as_dict() for d in DIRECTIONS},
                "queues": {
                    "uplink": self.config.uplink_queue,
                    "downlink": self.config.downlink_queue,
                },
                "bandwidth_log": str(self.log.path),
            }

    # -- lifecycle -------------------------------------------------------------------------

    def save_on_exit(self) -> None:
        """Record a clean shutdown (a restart then resumes the run without a fault)."""
        with self.lock:
            self._save(clean_exit=True)
            self.log.close()

    def _read_state(self) -> SavedState | None:
        try:
            return SavedState.read(self.config.state_file)
        except (ValueError, KeyError, TypeError, RouterError) as exc:
            # starting without it beats a restart loop that keeps OCU traffic stopped
            aside = f"{self.config.state_file}.unreadable"
            os.replace(self.config.state_file, aside)
            self.faults.append(f"the saved run was unreadable ({exc}; kept as {aside})")
            return None

    def _resume(self, saved: SavedState | None) -> None:
        if saved is None:
            return
        self.run, self.faults = saved.run, saved.faults + self.faults
        if not saved.clean_exit:
            self.faults.append(
                f"csrouter restarted after an unclean exit (last saved {utc_iso(saved.saved_at)}): "
                "counts since then and the packets it held were lost"
            )
        if self.run.armed:
            self.log.append([self._event("restarted")])
        log.warning("resumed run %s; faults: %s", self.run.run_id, self.faults)

    def _first_tick(self) -> float:
        if not self.run.armed or self.run.armed_at is None:
            return self._monotonic() + 1.0
        # keep the log's seconds counted from the arm
        since_arm = max(0.0, self._wall() - self.run.armed_at)
        self._second = int(since_arm) + 1
        return self._monotonic() + (self._second - since_arm)

    def _tick(self, now: float) -> None:
        """Write one line per direction for every whole second that has passed."""
        records: list[dict[str, Any]] = []
        armed_at = self.run.armed_at or self._wall()
        while now >= self._next_tick:
            self._next_tick += 1.0
            second, self._second = self._second, self._second + 1
            for direction in DIRECTIONS:
                meter = self.run.meters[direction]
                accepted, dropped = meter.take_second()
                records.append(
                    {
                        # the end of the second the line covers, not when it was written
                        "time": utc_iso(armed_at + second),
                        "second": second,
                        "run_id": self.run.run_id,
                        "direction": direction,
                        "bytes": accepted.payload_bytes,
                        "ip_bytes": accepted.ip_bytes,
                        "packets": accepted.packets,
                        "dropped_bytes": dropped.payload_bytes,
                        "cumulative_bytes": meter.accepted.payload_bytes,
                        "cumulative_ip_bytes": meter.accepted.ip_bytes,
                        "cap_remaining_bits": meter.remaining_bits,
                    }
                )
        self.log.append(records)
        self._save(clean_exit=False)

    def _event(self, event: str) -> dict[str, Any]:
        return {
            "time": utc_iso(self._wall()),
            "event": event,
            "run_id": self.run.run_id,
            "latency_ms": self.run.latency_ms,
            "caps_bits": {d: self.run.meters[d].cap_bits for d in DIRECTIONS},
        }

    def _save(self, *, clean_exit: bool) -> None:
        SavedState(self.run, clean_exit, self._wall(), self.faults).write(self.config.state_file)


def netem_available() -> bool:
    """Say whether this kernel has the netem qdisc (loaded or loadable)."""
    if os.path.isdir("/sys/module/sch_netem"):
        return True
    release = os.uname().release
    return any(
        os.path.exists(f"/lib/modules/{release}/kernel/net/sched/sch_netem.ko{suffix}")
        for suffix in ("", ".xz", ".zst", ".gz")
    )
