"""The router's bandwidth beside the simulator's run.mcap: bandwidth.mcap, made at collection.

The simulator cannot see the router's counters, so CloudSim writes them as a second MCAP
file once it has both logs; tools open the two together and merge them by topic and time.
Each second is placed at its end's wall-clock time less the simulator's start (the score
log's run_start): simulated time, for a run that kept real time.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from datetime import datetime
from pathlib import Path
from typing import Any

from csrouter.bandwidth_log import DIRECTIONS
from drcsim.mcaplog import write_bandwidth
from drcsim.rundir import BANDWIDTH_MCAP, SCORE, read_run_span

from cloudsim.competition.artifacts import LogStore, artifact_for, file_sha256
from cloudsim.extensions import db
from cloudsim.models import Artifact, Run

BANDWIDTH_LOG = "bandwidth.jsonl"


def bandwidth_samples(lines: Iterable[str], started: float) -> list[dict[str, Any]]:
    """Return the bandwidth log's per-second lines as samples for `write_bandwidth`, timed
    from `started` (epoch seconds); lines that are not the log's records are skipped."""
    caps: dict[str, int | None] = {direction: None for direction in DIRECTIONS}
    samples = []
    for line in lines:
        try:
            record = json.loads(line)
            if not isinstance(record, dict):
                continue
            if record.get("event") == "armed":
                given = record.get("caps_bits") or {}
                caps = {d: None if given.get(d) is None else int(given[d]) for d in DIRECTIONS}
            elif record.get("direction") in DIRECTIONS and "bytes" in record:
                end = datetime.fromisoformat(record["time"]).timestamp()
                samples.append(
                    {
                        "at": round(end - started, 3),
                        "direction": record["direction"],
                        "bits": 8 * int(record["bytes"]),
                        "used_bits": 8 * int(record.get("cumulative_bytes", 0)),
                        "cap_bits": caps[record["direction"]],
                    }
                )
        except (ValueError, KeyError, TypeError, AttributeError):
            continue  # e.g. a torn last line
    return samples


def store_bandwidth_mcap(run: Run, store: LogStore, staging: Path) -> str | None:
    """Write and store the run's bandwidth.mcap from its stored logs (again if repeated);
    return what it holds, None when the run has no bandwidth or score log to time it by."""
    bandwidth, score = artifact_for(run, BANDWIDTH_LOG), artifact_for(run, SCORE)
    if bandwidth is None or score is None:
        return None
    started = read_run_span(store.lines(score.location))[0]
    if started is None:
        return None
    samples = bandwidth_samples(store.lines(bandwidth.location), started)
    staging.mkdir(parents=True, exist_ok=True)
    local = staging / BANDWIDTH_MCAP
    count = write_bandwidth(local, samples)
    checksum, size = file_sha256(local), local.stat().st_size
    name = store.object_name(run.id, BANDWIDTH_MCAP)
    store.keep(local, name)
    artifact = artifact_for(run, BANDWIDTH_MCAP)
    if artifact is None:
        artifact = Artifact(filename=BANDWIDTH_MCAP, kind="bandwidth-mcap")
        run.artifacts.append(artifact)
    artifact.location, artifact.sha256, artifact.size = name, checksum, size
    db.session.flush()
    return f"{BANDWIDTH_MCAP}: {count} seconds' counts, {size} bytes, sha256 {checksum[:12]}"
