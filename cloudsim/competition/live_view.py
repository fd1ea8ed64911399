"""What a run looks like now: its row joined with the live figures the reader cached.

The run page's updates, the API's `GET /runs/{id}/live`, the dashboard's run card and
`cloudsim run watch` all show this one view, so they never disagree.
"""

from __future__ import annotations

import threading
from datetime import UTC, datetime
from typing import Any

import redis
from csrouter.bandwidth_log import DIRECTIONS, Bandwidth
from sqlalchemy import func, select

from cloudsim.competition import live
from cloudsim.competition.plots import bandwidth_charts, score_chart
from cloudsim.config import Config
from cloudsim.error_codes import RUN_SIM_SILENT, RUN_SIM_SLOW, describe
from cloudsim.extensions import db
from cloudsim.models import Job, Run, RunState, utcnow
from cloudsim.web import format_datetime

MAX_SECONDS = 24 * 3600  # a sample past this is not a run's: never grow a chart to it
DRAWN_KEPT = 64  # live runs whose last charts a web process keeps
_DRAWN: dict[int, tuple[tuple[Any, ...], dict[str, Any]]] = {}
_DRAWN_LOCK = threading.Lock()


def cached(config: Config, run: Run) -> tuple[dict[str, Any], int]:
    """Return the run's cached live figures and its count of bandwidth samples ({} and 0 if
    unreadable)."""
    if run.state != RunState.RUNNING:
        return {}, 0
    try:
        return live.read(live.connection(config), run.id)
    except redis.RedisError:  # the page still shows the row; its flags say nothing is live
        return {}, 0


def samples(config: Config, run: Run) -> list[list[float]]:
    """Return the run's cached bandwidth samples ([] if unreadable)."""
    try:
        return live.samples(live.connection(config), run.id)
    except redis.RedisError:
        return []


def live_status(config: Config, run: Run, figures: dict[str, Any] | None = None) -> dict[str, Any]:
    """Return the run's state and figures now (cached live ones while it runs)."""
    if figures is None:
        figures, _ = cached(config, run)
    sim = figures.get("sim") or {}
    used = figures.get("used") or {
        "uplink": run.uplink_bits_used,
        "downlink": run.downlink_bits_used,
    }
    used = {d: max(int(used[d]), getattr(run, f"{d}_bits_used")) for d in DIRECTIONS}
    caps = {"uplink": run.task.uplink_bits, "downlink": run.task.downlink_bits}
    spent = {
        d: _iso(getattr(run, f"{d}_spent_at")) or (figures.get("spent_at") or {}).get(d)
        for d in DIRECTIONS
    }
    events = figures.get("events") or [_event(e) for e in run.score_events]
    return {
        "id": run.id,
        "state": run.state.value,
        "live": bool(figures),
        "score": max(run.score, int(sim.get("score", 0))),
        "falls": max(run.falls, int(sim.get("falls", 0))),
        "sim_seconds": round(max(run.sim_seconds, float(sim.get("sim_time", 0.0))), 2),
        "timeout_s": run.task.timeout_s,
        "rtf": sim.get("rtf"),
        "end_reason": run.end_reason,
        "error": run.error,
        "error_code": run.error_code,
        "bits_used": used,
        "caps": caps,
        "bits_left": {d: max(0, caps[d] - used[d]) for d in DIRECTIONS},
        "spent_since": spent,
        "caps_spent": caps_spent(spent),
        "events": events,
        "heard": figures.get("heard") or {},
        "flags": flags(config, run, figures),
        "since": _iso(_state_since(run)),
    }


def flags(config: Config, run: Run, figures: dict[str, Any]) -> list[dict[str, str]]:
    """Return what is wrong with a running run now, each with its code and what it means."""
    if run.state != RunState.RUNNING:
        return []
    now = utcnow()
    running_for = (now - (run.running_at or run.started_at)).total_seconds()
    found = []
    heard = (figures.get("heard") or {}).get("sim")
    advanced = figures.get("sim_advanced_at")
    silent = [_age(now, t) for t in (heard, advanced)]
    if running_for > config.run_silent_seconds and any(
        age is None or age > config.run_silent_seconds for age in silent
    ):
        found.append(describe(RUN_SIM_SILENT))
    slow_since = figures.get("slow_since")
    slow_for = _age(now, slow_since)
    if slow_for is not None and slow_for >= config.run_rtf_alert_seconds:
        rtf = (figures.get("sim") or {}).get("rtf")
        found.append(describe(RUN_SIM_SLOW, rtf=rtf, threshold=config.run_rtf_alert))
    return found


def caps_spent(spent: dict[str, str | None]) -> str:
    """Say which caps are spent and since when."""
    parts = [
        f"{direction} spent since {format_datetime(datetime.fromisoformat(at), True)} UTC "
        "(traffic that way is dropped)"
        for direction, at in spent.items()
        if at is not None
    ]
    return "; ".join(parts) or "none"


def live_charts(run: Run, figures: dict[str, Any], samples: list[list[float]]) -> dict[str, Any]:
    """Return the score chart and the bandwidth charts drawn from the live figures."""
    events = figures.get("events") or [_event(e) for e in run.score_events]
    total, timeline = 0, []
    for event in events:
        total += int(event.get("points") or 0)
        timeline.append((float(event["sim_time"]), str(event["kind"]), total))
    end = float((figures.get("sim") or {}).get("sim_time", run.sim_seconds))
    caps = {"uplink": run.task.uplink_bits, "downlink": run.task.downlink_bits}
    bandwidth = bandwidth_charts(per_second(samples, caps)) if samples else []
    return {"score": score_chart(timeline, end), "bandwidth": bandwidth}


def per_second(samples: list[list[float]], caps: dict[str, int]) -> dict[str, Bandwidth]:
    """Return each direction's bits per whole second from cumulative (t, up, down) samples."""
    ordered = sorted((s for s in samples if 0 <= s[0] <= MAX_SECONDS), key=lambda s: s[0])
    last = int(ordered[-1][0]) if ordered else 0
    found: dict[str, Bandwidth] = {}
    for column, direction in enumerate(DIRECTIONS, start=1):
        totals, index, total = [], 0, 0
        for second in range(1, last + 1):
            while index < len(ordered) and ordered[index][0] <= second:
                total = int(ordered[index][column])
                index += 1
            totals.append(total)
        rates = [b - a for a, b in zip([0, *totals], totals, strict=False)]
        found[direction] = Bandwidth(
            bits_per_second=rates, used_bits=total, cap_bits=caps[direction]
        )
    return found


def charts_html(config: Config, run: Run, figures: dict[str, Any], count: int) -> dict[str, Any]:
    """Return the live charts as markup strings (for JSON), drawn once per change of the
    figures in this process however many pages poll them."""
    key = (
        count,
        len(figures.get("events") or []),
        (figures.get("sim") or {}).get("sim_time"),
    )
    with _DRAWN_LOCK:
        drawn = _DRAWN.get(run.id)
    if drawn is not None and drawn[0] == key:
        return drawn[1]
    charts = live_charts(run, figures, samples(config, run))
    html = {"score": str(charts["score"]), "bandwidth": [str(m) for m in charts["bandwidth"]]}
    with _DRAWN_LOCK:
        _DRAWN[run.id] = (key, html)
        while len(_DRAWN) > DRAWN_KEPT:
            _DRAWN.pop(next(iter(_DRAWN)))
    return html


def _event(event: Any) -> dict[str, Any]:
    return {
        "kind": event.kind,
        "sim_time": event.sim_time,
        "wall_time": _iso(event.wall_time),
        "checkpoint": event.checkpoint,
        "points": event.points,
        "description": event.description,
    }


def _state_since(run: Run) -> datetime | None:
    if run.state == RunState.RUNNING:
        return run.running_at
    if run.state == RunState.STOPPING:  # since its (first) stop job was started
        return db.session.scalar(
            select(func.min(Job.created_at)).where(
                Job.kind == "run.stop", Job.target_type == "run", Job.target_id == run.id
            )
        )
    if run.state in (RunState.FINISHED, RunState.ERROR):
        return run.finished_at
    return run.review_since if run.state == RunState.NEEDS_REVIEW else run.started_at


def _age(now: datetime, text: str | None) -> float | None:
    return None if not text else (now - datetime.fromisoformat(text)).total_seconds()


def _iso(moment: datetime | None) -> str | None:
    return moment.astimezone(UTC).isoformat() if moment else None
