"""bandwidth.mcap: the router's per-second counts made beside run.mcap when a run is collected."""

from __future__ import annotations

import json
from pathlib import Path

from flask import Flask

from cloudsim.competition.artifacts import LogStore
from cloudsim.competition.run_mcap import store_bandwidth_mcap
from cloudsim.extensions import db
from cloudsim.models import Team
from tests.competition.support import finished_run, open_task, store_log
from tests.support.mcap_files import validated_topics


def bandwidth_log(seconds: int) -> str:
    """Return a router's run log: armed 2.5 s before the score log's run_start, then each second."""
    lines = [
        {
            "time": "2026-11-22T08:56:01.500+00:00",
            "event": "armed",
            "run_id": "r1",
            "caps_bits": {"uplink": 115200, "downlink": None},
        }
    ]
    for second in range(1, seconds + 1):
        for direction, size in (("uplink", 10), ("downlink", 1000)):
            lines.append(
                {
                    "time": f"2026-11-22T08:56:{1 + second:02d}.500+00:00",
                    "second": second,
                    "direction": direction,
                    "bytes": size,
                    "cumulative_bytes": size * second,
                }
            )
    return "\n".join(json.dumps(line) for line in lines) + '\n{"torn'


def test_the_bandwidth_lines_up_with_the_run_and_is_stored_once(
    app: Flask, team_a: Team, tmp_path: Path
) -> None:
    run = finished_run(open_task(team_a.id), None, tmp_path)
    source = tmp_path / "bandwidth.jsonl"
    source.write_text(bandwidth_log(10))
    store_log(run, source, "bandwidth.jsonl")
    db.session.commit()
    store = LogStore(app.config["CLOUDSIM"])

    said = store_bandwidth_mcap(run, store, tmp_path / "staging")
    db.session.commit()

    assert said is not None and said.startswith("bandwidth.mcap: 16 seconds")
    artifact = next(a for a in run.artifacts if a.filename == "bandwidth.mcap")
    data = b"".join(store.stream(artifact.location))
    counts, first, last = validated_topics(data)
    # second 1 ended at 21:36:02.5, 0.5 s after the simulator's start; the three seconds
    # before the start are not the run's
    assert counts == {"/router/bandwidth": 16}
    assert (first, last) == (500_000_000, 7_500_000_000)
    again = store_bandwidth_mcap(run, store, tmp_path / "staging")  # a resumed stop
    db.session.commit()
    assert again == said
    assert [a.filename for a in run.artifacts].count("bandwidth.mcap") == 1


def test_a_run_without_a_bandwidth_log_gets_none(app: Flask, team_a: Team, tmp_path: Path) -> None:
    run = finished_run(open_task(team_a.id), None, tmp_path)
    assert store_bandwidth_mcap(run, LogStore(app.config["CLOUDSIM"]), tmp_path) is None
    assert "bandwidth.mcap" not in {a.filename for a in run.artifacts}
