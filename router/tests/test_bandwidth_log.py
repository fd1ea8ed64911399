"""Reading the bandwidth log: what the orchestrator's figures and plots are drawn from."""

from __future__ import annotations

import json

from csrouter.bandwidth_log import UPLINK, read_bandwidth_log

ARMED = {"event": "armed", "time": "2026-01-01T00:00:00+00:00", "caps_bits": {"uplink": 800}}


def line(**record: object) -> str:
    return json.dumps(record)


def test_malformed_lines_are_skipped_and_the_rest_still_reads() -> None:
    good = [
        json.dumps(ARMED),
        line(direction=UPLINK, second=1, bytes=10, cumulative_bytes=10, cap_remaining_bits=720),
        line(direction=UPLINK, second=2, bytes=5, cumulative_bytes=15, cap_remaining_bits=680),
    ]
    bad = [
        "[1]",
        '"text"',
        '{"direction": "uplink", "bytes": 1, "time": "bad"}',
        '{"direction": "uplink", "bytes": "many", "second": 3}',
        '{"direction": "uplink", "bytes": 1, "second": 1e12}',  # would build 10^12 seconds
        '{"event": "armed", "time": 5}',
        '{"event": "disarmed", "counters": {"uplink": {"spent_at": "never"}}}',
        '{"direction": "uplink", "bytes": 1, "second',  # torn
    ]
    clean = read_bandwidth_log(good)[UPLINK]
    read = read_bandwidth_log([good[0], *bad[:4], good[1], *bad[4:], good[2]])[UPLINK]
    assert read == clean
    assert read.bits_per_second == [80, 40] and read.used_bits == 120
    assert read.cap_bits == 800 and read.remaining_bits == 680
