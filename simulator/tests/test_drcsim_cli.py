"""The command-line entry points that other parts of CloudSim call."""

from __future__ import annotations

import json
import subprocess
import sys


def _drcsim(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "drcsim.cli", *args], capture_output=True, text=True, timeout=120
    )


def test_selftest_prints_one_json_line_with_rtf_and_ok() -> None:
    done = _drcsim("selftest", "--seconds", "0.5", "--json", "--min-rtf", "0")
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert result["ok"] is True and result["rtf"] > 0 and result["sim_s"] == 0.5


def test_selftest_fails_when_the_rtf_is_below_the_minimum() -> None:
    done = _drcsim("selftest", "--seconds", "0.2", "--json", "--no-sensors", "--min-rtf", "1e9")
    assert done.returncode == 1 and json.loads(done.stdout)["ok"] is False


def test_bench_reports_every_world_and_the_round_trip() -> None:
    done = _drcsim("bench", "--json", "--seconds", "0.1", "--samples", "20", "--split")
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert [(r["world"], r["sensors"]) for r in result["rtf"]] == [
        (w, s) for w in ("vrc_task_1", "vrc_task_2", "vrc_task_3") for s in (False, True)
    ]  # one row each: the walker is the only balance
    assert all(r["cpu_rtf"] > 0 and r["rtf"] > 0 for r in result["rtf"])
    loaded = [r for r in result["rtf"] if r["sensors"]]
    assert all(r["cpu_vs_no_sensors"] > 0 for r in loaded)  # against the same run's reference
    assert result["target"]["on"] == "cpu_rtf" and result["target"]["rtf"] == 1.5
    assert result["target"]["met"] == all(r["cpu_rtf"] >= 1.5 for r in loaded)
    assert len(result["load_average"]["before"]) == len(result["load_average"]["after"]) == 3
    split = loaded[0]["cpu_ms_per_sim_s"]  # where the CPU time went, each sensor on its own
    assert {"physics", "behaviours", "controller", "camera", "lidar", "other"} <= set(split)
    assert split["physics"] > 0 and split["camera"] > 0
    assert result["round_trip"]["samples"] == 20
    assert result["round_trip"]["p99_ms"] >= result["round_trip"]["p50_ms"] > 0


def test_unknown_world_is_a_one_line_error() -> None:
    done = _drcsim("serve", "--world", "vrc_task_7")
    assert done.returncode != 0 and "invalid choice" in done.stderr


def test_a_sensor_setting_no_sensor_can_have_is_a_one_line_error() -> None:
    for bad, says in (
        ("lidar_min_range=40", "lidar_min_range must be below lidar_range"),
        ("camera_hz=0", "camera_hz must be a finite number above 0"),
        ("lidar_noise=nan", "lidar_noise must be a finite number"),
    ):
        done = _drcsim("serve", "--world", "vrc_task_1", "--sensor", bad, "--time-limit", "1")
        assert done.returncode != 0 and f"bad --sensor setting: {says}" in done.stderr, bad


def test_ladder_runs_reference_controllers_over_the_network_and_prints_the_table() -> None:
    done = _drcsim(
        "ladder",
        "--json",
        "--controller",
        "naive",
        "--controller",
        "careful",
        "--world",
        "vrc_task_2",
        "--config",
        "1",
        "--time-limit",
        "4",
        "--jobs",
        "2",
    )
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert {(r["controller"], r["world"], r["config"]) for r in result["runs"]} == {
        ("naive", "vrc_task_2", "1"),
        ("careful", "vrc_task_2", "1"),
    }
    for row in result["runs"]:  # ended by the run, or stopped after a fall it gave up on
        assert row["reason"] in ("time_limit", "complete") or (
            row["reason"] == "stopped" and row["falls"] >= 1 and "fell" in row["gave_up"]
        )
        assert 0 <= row["checkpoints"] <= 4
    assert result["totals"]["naive"]["of"] == 4 and result["jobs"] == 2
