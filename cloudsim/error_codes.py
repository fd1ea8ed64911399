"""Stable codes of what goes wrong with runs and launches: each with its cause and what to do.

A code never changes meaning once published: pages and the API show it next to the free text,
and the documentation's error codes page is this table (docs_tools/reference.py puts it there).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class ErrorCode:
    """A failure's code, its cause, and what the person who sees it can do."""

    code: str
    cause: str
    remedy: str


RUN_START_FAILED = "RUN-START-FAILED"
RUN_STOP_FAILED = "RUN-STOP-FAILED"
RUN_ROUTER_FAULT = "RUN-ROUTER-FAULT"
RUN_SIM_SILENT = "RUN-SIM-SILENT"
RUN_SIM_SLOW = "RUN-SIM-SLOW"
RUN_END_UNKNOWN = "RUN-END-UNKNOWN"
RUN_REVIEWED_FAILED = "RUN-REVIEWED-FAILED"
LAUNCH_SIM_SLOW = "LAUNCH-SIM-SLOW"
LAUNCH_VERIFY_FAILED = "LAUNCH-VERIFY-FAILED"
LAUNCH_UNREACHABLE = "LAUNCH-UNREACHABLE"
LAUNCH_PROVIDER = "LAUNCH-PROVIDER"
LAUNCH_FAILED = "LAUNCH-FAILED"

CODES: dict[str, ErrorCode] = {
    c.code: c
    for c in (
        ErrorCode(
            RUN_START_FAILED,
            "A step of the run's start (arming the router, starting the simulator) failed; "
            "the run was stopped and nothing of it counts.",
            "Read the error on the run page; if the task's window is still open, start the "
            "run again, otherwise ask an officer.",
        ),
        ErrorCode(
            RUN_STOP_FAILED,
            "A step of the run's stop (stopping the simulator, disarming the router, "
            "collecting the logs) failed; CloudSim tries it again.",
            "Wait: the stop is retried. If it keeps failing the run goes to needs review.",
        ),
        ErrorCode(
            RUN_ROUTER_FAULT,
            "The router's daemon reported a fault mid-run; the team's traffic is held until "
            "it is fixed.",
            "Nothing: the note clears once the router is healthy. An officer may invalidate "
            "the run if the fault cost the team.",
        ),
        ErrorCode(
            RUN_SIM_SILENT,
            "The simulator has not answered, or its simulated time has not moved, for "
            "CLOUDSIM_RUN_SILENT_SECONDS.",
            "Team: check your controller still talks to it. Officers: check the sim machine; "
            "the run is stopped at its time limit plus CLOUDSIM_RUN_GRACE_SECONDS regardless.",
        ),
        ErrorCode(
            RUN_SIM_SLOW,
            "The simulator's real-time factor has stayed under CLOUDSIM_RUN_RTF_ALERT for "
            "CLOUDSIM_RUN_RTF_ALERT_SECONDS: the run is slower than real time.",
            "Officers: the sim machine is overloaded or too small (see docs/live-runs.md, "
            "sizing); consider invalidating the run and giving the team another.",
        ),
        ErrorCode(
            RUN_END_UNKNOWN,
            "CloudSim could not establish how the run ended (its stop failed "
            "repeatedly); the run waits in needs review.",
            "Officers: look at the run's machines and logs, then accept an end or mark the "
            "run failed on its page (audited).",
        ),
        ErrorCode(
            RUN_REVIEWED_FAILED,
            "An officer reviewed a run whose end could not be established and marked it "
            "failed; it does not count.",
            "Ask the officers for another run of the task.",
        ),
        ErrorCode(
            LAUNCH_SIM_SLOW,
            "The simulator machine's self-test ran slower than CLOUDSIM_SIM_MIN_RTF (the "
            "figure measured is in the error).",
            "Launch on a larger machine size (docs/live-runs.md, sizing), or lower "
            "CLOUDSIM_SIM_MIN_RTF only for practice.",
        ),
        ErrorCode(
            LAUNCH_VERIFY_FAILED,
            "A verification check failed: a machine reached what it must not, or not what "
            "it must (the error lists each check).",
            "Read the failed checks; fix the network or firewall, then retry the launch.",
        ),
        ErrorCode(
            LAUNCH_UNREACHABLE,
            "CloudSim could not reach a machine over SSH within the deadline.",
            "Check the provider's console for the machine, then retry the launch.",
        ),
        ErrorCode(
            LAUNCH_PROVIDER,
            "The cloud provider refused or failed a request (quota, size, image, network).",
            "Read the provider's message in the error; fix the account or settings, retry.",
        ),
        ErrorCode(
            LAUNCH_FAILED,
            "Another step of the launch failed (the error names the stage).",
            "Read the error and the job log on the constellation page; retry the launch.",
        ),
    )
}


def describe(code: str, **figures: Any) -> dict[str, str]:
    """Return a code with its cause and remedy (and any figures) for a page or the API."""
    entry = CODES[code]
    found = {"code": code, "cause": entry.cause, "remedy": entry.remedy}
    if figures:
        found["figures"] = ", ".join(f"{k} {v}" for k, v in figures.items() if v is not None)
    return found


def markdown_table() -> str:
    """Return the table of codes as the documentation's error codes page shows it."""
    rows = ["| Code | Cause | What you can do |", "| --- | --- | --- |"]
    rows += [f"| `{c.code}` | {c.cause} | {c.remedy} |" for c in CODES.values()]
    return "\n".join(rows) + "\n"
