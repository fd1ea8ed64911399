"""Replay: re-simulate a logged run from t=0 with its seed and command log, then compare."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from drcsim.engine import RunOptions, Simulation
from drcsim.errors import ReplayMismatch
from drcsim.protocol import check_command
from drcsim.rundir import WORLD, read_final, read_meta
from drcsim.runlog import read_commands, read_states, state_digest
from drcsim.scene import TIMESTEP
from drcsim.worlds import read_world_file


@dataclass(frozen=True)
class ReplayResult:
    """What a replay found."""

    steps: int
    states_checked: int
    final_digest: str
    score: int
    end_reason: str | None  # None: the run did not end by itself (stopped or closed from outside)
    falls: int = 0
    # the scorer's checkpoint and fall events, as the replay produced them (no wall time)
    events: tuple[dict[str, Any], ...] = ()

    @property
    def sim_seconds(self) -> float:
        """Return the simulated time the replay reached."""
        return round(self.steps * TIMESTEP, 6)

    def as_dict(self) -> dict[str, Any]:
        """Return the result as plain data."""
        return {
            "ok": True,
            "steps": self.steps,
            "states_checked": self.states_checked,
            "final_state_sha256": self.final_digest,
            "score": self.score,
            "end_reason": self.end_reason,
            "falls": self.falls,
            "sim_seconds": self.sim_seconds,
            "events": list(self.events),
        }


def replay(log_dir: Path) -> ReplayResult:
    """Re-simulate the run in `log_dir`; raise ReplayMismatch at the first divergence."""
    meta, final = read_meta(log_dir), read_final(log_dir)
    recorded_states = read_states(log_dir)
    checked = 0
    handed = log_dir / WORLD
    document = read_world_file(handed) if handed.exists() else None
    options = RunOptions(time_limit_s=meta["time_limit_s"], world_document=document)
    sim = Simulation(meta["world"], meta["config"], options)
    if meta.get("world_digest", sim.spec.digest) != sim.spec.digest:
        raise ReplayMismatch("the world document differs from the one the run was built from")
    if sim.spec.seed != meta["seed"]:
        raise ReplayMismatch(f"configuration seed is {sim.spec.seed}, the log says {meta['seed']}")

    def advance_to(step: int) -> None:
        nonlocal checked
        while sim.step_count < step and not sim.ended:
            sim.step(min(10 - sim.step_count % 10, step - sim.step_count))
            if sim.step_count % 10 == 0:
                record = next(recorded_states, None)
                if record is None:
                    raise ReplayMismatch(f"the state log ends before step {sim.step_count}")
                expected = (record["step"], record["digest"])
                if expected != (sim.step_count, state_digest(sim.state_vector())[:16]):
                    raise ReplayMismatch(
                        f"state differs at step {sim.step_count} (t = {sim.sim_time:.3f} s)"
                    )
                checked += 1

    try:
        for step, command in read_commands(log_dir):
            advance_to(step)
            # a command log is evidence from outside: checked as the server checked it live
            sim.apply_command(check_command(command))
        advance_to(int(final["step"]))
        digest = state_digest(sim.state_vector())
        if sim.step_count != final["step"] or digest != final["state_sha256"]:
            raise ReplayMismatch(f"final state differs (step {sim.step_count} vs {final['step']})")
        kept = ("event", "checkpoint", "falls", "sim_time")
        events = tuple(
            {key: value for key, value in event.items() if key in kept}
            for event in sim.scorer.events
            if event["event"] in ("checkpoint", "fall")
        )
        return ReplayResult(
            sim.step_count,
            checked,
            digest,
            sim.scorer.reached,
            sim.scorer.end_reason,
            sim.scorer.falls,
            events,
        )
    finally:
        sim.client.disconnect()
