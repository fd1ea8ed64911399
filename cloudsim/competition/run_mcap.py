"""The router's bandwidth beside the simulator's run.mcap: bandwidth.mcap, made at collection.

The simulator cannot see the router's counters, so CloudSim writes them as a second MCAP
file once it has both logs; tools open the two together and merge them by topic and time.
"""

from __future__ import annotations

import json
from datetime import datetime
from pathlib import Path

from csrouter.bandwidth_log import DIRECTIONS, read_bandwidth_log
from drcsim.mcaplog import write_bandwidth
from drcsim.rundir import BANDWIDTH_MCAP, SCORE, read_run_span

from cloudsim.competition.artifacts import LogStore, artifact_for, file_sha256
from cloudsim.extensions import db
from cloudsim.models import Artifact, Run

BANDWIDTH_LOG = "bandwidth.jsonl"


def armed_at(lines: list[str]) -> float | None:
    """Return when (epoch seconds) the bandwidth log says the router was armed."""
    for line in lines:
        try:
            record = json.loads(line)
            if isinstance(record, dict) and record.get("event") == "armed":
                return datetime.fromisoformat(record["time"]).timestamp()
        except (ValueError, KeyError, TypeError):
            continue
    return None


def store_bandwidth_mcap(run: Run, store: LogStore, staging: Path) -> str | None:
    """Write and store the run's bandwidth.mcap from its stored logs (again if repeated);
    return what it says, None when the run has no bandwidth log."""
    bandwidth = artifact_for(run, BANDWIDTH_LOG)
    if bandwidth is None:
        return None
    lines = list(store.lines(bandwidth.location))
    usage = read_bandwidth_log(lines)
    score = artifact_for(run, SCORE)
    started = read_run_span(store.lines(score.location))[0] if score is not None else None
    armed = armed_at(lines)
    # the router is armed before the simulator starts: its seconds count from earlier
    offset = armed - started if armed is not None and started is not None else 0.0
    series = {d: (usage[d].bits_per_second, usage[d].cap_bits) for d in DIRECTIONS}
    staging.mkdir(parents=True, exist_ok=True)
    local = staging / BANDWIDTH_MCAP
    count = write_bandwidth(local, series, offset)
    checksum, size = file_sha256(local), local.stat().st_size
    name = store.object_name(run.id, BANDWIDTH_MCAP)
    store.keep(local, name)
    artifact = artifact_for(run, BANDWIDTH_MCAP)
    if artifact is None:
        artifact = Artifact(filename=BANDWIDTH_MCAP, kind="bandwidth-mcap")
        run.artifacts.append(artifact)
    artifact.location, artifact.sha256, artifact.size = name, checksum, size
    db.session.flush()
    return f"{BANDWIDTH_MCAP}: {count} messages, {size} bytes, sha256 {checksum[:12]}"
