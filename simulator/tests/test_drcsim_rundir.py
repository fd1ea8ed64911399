"""The run directory's contract: the score log reader CloudSim scores runs with."""

from __future__ import annotations

import pytest
from drcsim.rundir import FILES, SCORE, ScoreLogError, read_score_log, serve_argv

LOG = [
    '{"event": "run_start", "score": 0, "sim_time": 0.0, "wall_time": 1795337764.0}',
    '{"checkpoint": 1, "event": "checkpoint", "name": "gate 1", "points": 1, "score": 1, '
    '"sim_time": 5.01, "wall_time": 1795337765.0}',
    '{"event": "fall", "falls": 1, "score": 1, "sim_time": 7.5, "wall_time": 1795337766.0}',
    '{"checkpoint": 2, "event": "checkpoint", "name": "gate 2", "points": 1, "score": 2, '
    '"sim_time": 18.6, "wall_time": 1795337767.0}',
    '{"event": "run_end", "falls": 1, "reason": "time_limit", "score": 2, "sim_time": 60.0, '
    '"wall_time": 1795337768.0}',
]


def test_the_score_log_gives_checkpoints_falls_and_the_end() -> None:
    score = read_score_log(LOG)
    assert (score.score, score.falls, score.end_reason, score.sim_seconds) == (
        2,
        1,
        "time_limit",
        60.0,
    )
    assert [e.kind for e in score.events] == ["checkpoint", "fall", "checkpoint", "run_end"]
    assert score.events[0].description == "gate 1" and score.events[0].checkpoint == 1


def test_a_torn_last_line_is_ignored_but_a_broken_middle_line_is_an_error() -> None:
    assert read_score_log([*LOG[:3], '{"event": "checkp']).score == 1
    with pytest.raises(ScoreLogError, match="line 2"):
        read_score_log([LOG[0], "garbage", LOG[1]])


def test_serve_argv_is_what_drcsim_serve_parses() -> None:
    from drcsim.cli import build_parser

    argv = serve_argv(
        "drcsim",
        "vrc_task_2",
        3,
        bind="10.0.0.51",
        allow=["10.0.0.0/24", "10.8.0.0/24"],
        log_dir="/var/lib/runs/7",
        time_limit_s=1800,
    )
    args = build_parser().parse_args(argv[1:])
    assert (args.world, args.config, args.bind, args.allow, str(args.log_dir)) == (
        "vrc_task_2",
        "3",
        "10.0.0.51",
        ["10.0.0.0/24", "10.8.0.0/24"],
        "/var/lib/runs/7",
    )
    assert args.time_limit == 1800.0 and SCORE in FILES
