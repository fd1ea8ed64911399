"""What a run notice says: the run's summary (as JSON and as an e-mail) and its links."""

from __future__ import annotations

from email.message import EmailMessage
from typing import Any

from flask import current_app

from cloudsim.config import Config
from cloudsim.models import Run

SUBJECTS = {
    "started": "started",
    "ended": "ended",
    "failed": "failed",
    "needs_review": "needs an officer's review",
}


def _link(path: str) -> str:
    config: Config = current_app.config["CLOUDSIM"]
    return f"{config.public_url}{path}"


def run_summary(run: Run) -> dict[str, Any]:
    """Return a run's summary: state, score, falls, simulated time, bits left, links."""
    task = run.task
    return {
        "id": run.id,
        "team": run.team.name,
        "task": task.name,
        "state": run.state.value,
        "score": run.score,
        "falls": run.falls,
        "sim_seconds": round(run.sim_seconds, 3),
        "timeout_s": task.timeout_s,
        "uplink_bits_left": max(task.uplink_bits - run.uplink_bits_used, 0),
        "downlink_bits_left": max(task.downlink_bits - run.downlink_bits_used, 0),
        "end_reason": run.end_reason,
        "error": run.error,
        "officer_note": run.officer_note,
        "links": {
            "run": _link(f"/runs/{run.id}"),
            "replay": _link(f"/runs/{run.id}/view"),
            "logs": {a.filename: _link(f"/runs/{run.id}/logs/{a.id}") for a in run.artifacts},
        },
    }


def run_email(payload: dict[str, Any], sender: str, to: str) -> EmailMessage:
    """Return the e-mail telling one person about a run's event."""
    run = payload["run"]
    event = payload["event"].removeprefix("run.")
    message = EmailMessage()
    message["From"] = sender
    message["To"] = to
    message["Subject"] = f"CloudSim: run {run['id']} of {run['task']} {SUBJECTS[event]}"
    lines = [
        f"Run {run['id']} of task {run['task']} (team {run['team']}) {SUBJECTS[event]}.",
        "",
        f"State: {run['state']}",
        f"Score: {run['score']}",
        f"Falls: {run['falls']}",
        f"Simulated time: {run['sim_seconds']:.1f} s of {run['timeout_s']} s",
        f"Bits left: {run['uplink_bits_left']} up, {run['downlink_bits_left']} down",
    ]
    if run["end_reason"]:
        lines.append(f"Ended by: {run['end_reason']}")
    if run["error"]:
        lines.append(f"Error: {run['error']}")
    if run.get("officer_note"):  # .get: notices recorded before the note was in the summary
        lines.append(f"Officer's note: {run['officer_note']}")
    if event == "needs_review":
        # the run is not live and not ranked: say who acts and that another e-mail follows
        lines += [
            "",
            "CloudSim could not establish how this run ended. An officer checks its logs and",
            "settles it (finished or failed); you get another e-mail when they do.",
        ]
    lines += ["", f"Run: {run['links']['run']}", f"Replay: {run['links']['replay']}"]
    lines += [f"Log {name}: {url}" for name, url in run["links"]["logs"].items()]
    lines += ["", "You can stop these e-mails on your account page."]
    message.set_content("\n".join(lines) + "\n")
    return message
