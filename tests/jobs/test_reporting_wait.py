"""A long wait with a deadline of its own reports itself, so the watchdog does not stop it."""

from __future__ import annotations

import threading

from cloudsim.jobs.heartbeat import reporting_wait


def test_a_reporting_wait_logs_while_it_lasts_and_stops_after() -> None:
    lines: list[str] = []
    told = threading.Event()

    def log_line(line: str) -> None:
        lines.append(line)
        told.set()

    with reporting_wait(log_line, "building the image", every=0.05):
        assert told.wait(10)  # the block's own work, here: waiting to be reported
    assert lines[0].startswith("still building the image (") and lines[0].endswith(" s)")
    # the ticker ended with the block: nothing can report after it
    assert not [t for t in threading.enumerate() if t.name == "job-reporting-wait"]
