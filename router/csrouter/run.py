"""A run's settings and counters, and the state file that survives a daemon restart."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from csrouter.bandwidth_log import DIRECTIONS, DOWNLINK, UPLINK, utc_iso
from csrouter.config import check_cap, check_latency
from csrouter.meter import DirectionMeter


@dataclass
class Run:
    """What is armed now: latency, caps and counters per direction (or idle, uncapped)."""

    latency_ms: int
    run_id: str | None = None
    armed: bool = False
    armed_at: float | None = None  # wall clock, seconds since the epoch
    meters: dict[str, DirectionMeter] = field(
        default_factory=lambda: {d: DirectionMeter() for d in DIRECTIONS}
    )

    @classmethod
    def arm(
        cls,
        *,
        latency_ms: int,
        uplink_bits: int | None,
        downlink_bits: int | None,
        run_id: str | None,
        now: float,
    ) -> Run:
        """Return a freshly armed run with zeroed counters."""
        return cls(
            latency_ms=check_latency(latency_ms),
            run_id=run_id,
            armed=True,
            armed_at=now,
            meters={
                UPLINK: DirectionMeter(check_cap("uplink_bits", uplink_bits)),
                DOWNLINK: DirectionMeter(check_cap("downlink_bits", downlink_bits)),
            },
        )

    def counters(self, now: float) -> dict[str, Any]:
        """Return the run's identity and every direction's counts as JSON-able values."""
        return {
            "run_id": self.run_id,
            "armed": self.armed,
            "armed_at": None if self.armed_at is None else utc_iso(self.armed_at),
            "elapsed_s": None if self.armed_at is None else round(now - self.armed_at, 3),
            "latency_ms": self.latency_ms,
            **{direction: self.meters[direction].snapshot() for direction in DIRECTIONS},
        }

    def to_state(self) -> dict[str, Any]:
        """Return what a restarted daemon needs to carry on with this run."""
        return {
            "latency_ms": self.latency_ms,
            "run_id": self.run_id,
            "armed": self.armed,
            "armed_at": self.armed_at,
            "meters": {d: self.meters[d].snapshot() for d in DIRECTIONS},
        }

    @classmethod
    def from_state(cls, data: dict[str, Any]) -> Run:
        """Rebuild a run saved by to_state."""
        return cls(
            latency_ms=check_latency(int(data["latency_ms"])),
            run_id=data["run_id"],
            armed=bool(data["armed"]),
            armed_at=data["armed_at"],
            meters={d: DirectionMeter.restore(data["meters"][d]) for d in DIRECTIONS},
        )


@dataclass
class SavedState:
    """The state file: the run, whether the daemon stopped cleanly, faults not yet cleared."""

    run: Run
    clean_exit: bool
    saved_at: float
    faults: list[str]

    def write(self, path: str) -> None:
        """Replace the state file atomically."""
        target = Path(path)
        target.parent.mkdir(parents=True, exist_ok=True)
        scratch = target.with_name(f".{target.name}.{os.getpid()}")
        scratch.write_text(
            json.dumps(
                {
                    "run": self.run.to_state(),
                    "clean_exit": self.clean_exit,
                    "saved_at": self.saved_at,
                    "faults": self.faults,
                }
            )
        )
        os.replace(scratch, target)

    @classmethod
    def read(cls, path: str) -> SavedState | None:
        """Return the saved state, None when there is none."""
        try:
            data = json.loads(Path(path).read_text())
        except FileNotFoundError:
            return None
        return cls(
            run=Run.from_state(data["run"]),
            clean_exit=bool(data["clean_exit"]),
            saved_at=float(data["saved_at"]),
            faults=[str(fault) for fault in data["faults"]],
        )
