"""The VRC ranking, and the plots from csrouter's bandwidth log (drcsim tests its score log)."""

from __future__ import annotations

import json

import pytest
from csrouter.bandwidth_log import Bandwidth, read_bandwidth_log

from cloudsim.competition.live_view import per_second
from cloudsim.competition.plots import (
    bandwidth_charts,
    cumulative,
    moving_average,
    score_chart,
)
from cloudsim.competition.scoring import RunResult, rank


def result(checkpoints: int, used: int, sim: float = 1800.0, complete: bool = False) -> RunResult:
    return RunResult(checkpoints, 1000, used, 1800, sim, complete)


def test_ranking_puts_checkpoints_first_then_uplink_left_then_seconds_left() -> None:
    standings = rank(
        {
            (1, "Alpha"): [result(4, 900), result(2, 100)],  # 6 points, 50% left
            (2, "Bravo"): [result(3, 100), result(3, 100)],  # 6 points, 90% left
            (3, "Charlie"): [result(4, 100, 600, True), result(2, 100)],  # 6, 90%, 1200 s
            (4, "Delta"): [result(8, 1000)],  # 8 points, nothing left
            (5, "Echo"): [],
        }
    )
    assert [s.team for s in standings] == ["Delta", "Charlie", "Bravo", "Alpha", "Echo"]
    assert [s.rank for s in standings] == [1, 2, 3, 4, 5]
    charlie = standings[1]
    assert charlie.uplink_share_left == pytest.approx(0.9) and charlie.seconds_left == 1200


def test_equal_figures_share_a_rank() -> None:
    standings = rank({(1, "A"): [result(2, 500)], (2, "B"): [result(2, 500)], (3, "C"): []})
    assert [(s.team, s.rank) for s in standings] == [("A", 1), ("B", 1), ("C", 3)]


def bandwidth_log() -> list[str]:
    lines = [
        json.dumps(
            {
                "time": "2026-06-17T16:00:00.000+00:00",
                "event": "armed",
                "caps_bits": {"uplink": 80_000, "downlink": None},
            }
        )
    ]
    total = {"uplink": 0, "downlink": 0}
    for second in range(1, 13):
        for direction, size in (("uplink", 1000 if second <= 4 else 0), ("downlink", 500)):
            total[direction] += size
            lines.append(
                json.dumps(
                    {
                        "time": f"2026-06-17T16:00:{second:02d}.000+00:00",
                        "direction": direction,
                        "bytes": size,
                        "cumulative_bytes": total[direction],
                        "cap_remaining_bits": None,
                    }
                )
            )
    return [*lines, '{"time": "2026-06-17T16:00:13.0', ""]


def test_bandwidth_log_gives_bits_per_second_and_totals() -> None:
    usage = read_bandwidth_log(bandwidth_log())
    assert usage["uplink"].bits_per_second == [8000] * 4 + [0] * 8
    assert usage["uplink"].used_bits == 32_000 and usage["uplink"].cap_bits == 80_000
    assert usage["downlink"].used_bits == 48_000 and usage["downlink"].cap_bits is None


def test_moving_averages_and_totals() -> None:
    values = [8000.0] * 4 + [0.0] * 8
    assert moving_average(values, 2)[:6] == [8000, 8000, 8000, 8000, 4000, 0]
    assert moving_average(values, 10)[9] == pytest.approx(3200)
    assert moving_average(values, 10)[11] == pytest.approx(1600)  # samples 2..11
    assert cumulative([1.0, 2.0, 3.0]) == [1.0, 3.0, 6.0]


def test_charts_are_svg_with_both_averages_and_the_cap() -> None:
    charts = bandwidth_charts(read_bandwidth_log(bandwidth_log()))
    assert len(charts) == 4
    up_rate, up_used = charts[0], charts[1]
    assert up_rate.startswith("<svg") and 'data-series="2 s average"' in up_rate
    assert 'data-series="10 s average"' in up_rate
    assert 'class="limit"' in up_used and "cap 80k" in up_used
    assert 'class="limit"' not in charts[3]  # downlink without a cap
    timeline = score_chart([(5.0, "checkpoint", 1), (7.5, "fall", 1)], 60.0)
    assert 'data-series="checkpoints"' in timeline and "<script" not in timeline


def test_chart_text_is_escaped() -> None:
    chart = score_chart([], 1.0)
    from cloudsim.competition.plots import Series, line_chart

    hostile = line_chart("<b>x</b>", [Series("<script>", [(0, 0), (1, 1)])], x_label="", y_label="")
    assert "<script>" not in hostile and "&lt;script&gt;" in hostile
    assert chart.count("<svg") == 1


def test_bandwidth_lines_go_to_the_second_they_cover_even_when_written_late() -> None:
    lines = [
        json.dumps({"event": "armed", "time": "2026-06-17T16:00:00.000+00:00"}),
        *(
            json.dumps(
                {
                    "time": "2026-06-17T16:00:09.000+00:00",  # a restart wrote three at once
                    "second": second,
                    "direction": "uplink",
                    "bytes": 100 * second,
                    "cumulative_bytes": sum(100 * s for s in range(1, second + 1)),
                }
            )
            for second in (1, 2, 3)
        ),
    ]
    usage = read_bandwidth_log(lines)
    assert usage["uplink"].bits_per_second == [800, 1600, 2400]
    assert usage["uplink"].used_bits == 4800


def test_the_bits_used_chart_is_scaled_to_the_use_with_the_cap_marked() -> None:
    usage = {
        "uplink": Bandwidth(bits_per_second=[1000] * 10, used_bits=10_000, cap_bits=8_000_000),
        "downlink": Bandwidth(bits_per_second=[1000] * 10, used_bits=10_000, cap_bits=10_500),
    }
    up_used, down_used = bandwidth_charts(usage)[1], bandwidth_charts(usage)[3]
    # far below the cap: the scale is the use's (10k, not 8M), the cap marked above it
    assert ">10.5k</text>" in up_used and 'data-off-scale="true"' in up_used
    assert "cap 8M above the scale (0.1% used)" in up_used
    # near the cap: the cap is the line inside the chart
    assert 'class="limit"' in down_used and "data-off-scale" not in down_used


def test_live_samples_become_bits_per_second() -> None:
    samples = [[0.4, 0, 0], [1.2, 800, 80], [2.1, 800, 160], [3.0, 2400, 160]]
    found = per_second(samples, {"uplink": 5000, "downlink": 100})
    assert found["uplink"].bits_per_second == [0, 800, 1600]
    assert found["downlink"].bits_per_second == [0, 80, 80]
    assert found["uplink"].used_bits == 2400 and found["downlink"].cap_bits == 100
    assert per_second([], {"uplink": 1, "downlink": 1})["uplink"].bits_per_second == []
