"""A constellation's life: the one place its state (and its machines') changes and the jobs
each change starts are enqueued.

pending -> launching -> ready | error; error -> pending (retry); any -> terminating ->
terminated | terminate_incomplete (a machine not cleaned); terminate_incomplete -> terminating
(retry). The service checks who may ask and what is allowed; the job bodies do the work;
both call here to move the state.
"""

from __future__ import annotations

from dataclasses import dataclass

from cloudsim.auth.policy import Actor
from cloudsim.jobs.control import cancel_jobs
from cloudsim.jobs.runner import Payload
from cloudsim.jobs.service import enqueue
from cloudsim.models import Constellation, ConstellationState, Job, Machine, MachineState
from cloudsim.models.machines import GONE

# The error of a constellation whose terminate is incomplete starts with this.
TERMINATE_INCOMPLETE = "terminate incomplete: "


@dataclass(frozen=True)
class ConstellationJob(Payload):
    """The payload of every constellation job: which constellation."""

    constellation_id: int

    def about(self) -> tuple[str, int]:
        return ("constellation", self.constellation_id)


def _start_job(actor: Actor, constellation: Constellation, kind: str) -> Job:
    """Enqueue a job about the constellation."""
    return enqueue(kind, actor, ConstellationJob(constellation.id), team_id=constellation.team_id)


def start_launch(actor: Actor, constellation: Constellation) -> Job:
    """Start the job that launches a constellation recorded as pending."""
    return _start_job(actor, constellation, "constellation.launch")


def retry(actor: Actor, constellation: Constellation) -> Job:
    """Set a constellation in error back to pending and start its launch again."""
    constellation.state = ConstellationState.PENDING
    return start_launch(actor, constellation)


TERMINATE_JOB = "constellation.terminate"


def start_terminate(actor: Actor, constellation: Constellation) -> Job:
    """Mark a constellation terminating, ask its other jobs (a launch, an access push) to stop
    at their next step, and start the job that releases its resources."""
    constellation.state = ConstellationState.TERMINATING
    cancel_jobs(
        "constellation",
        constellation.id,
        f"{constellation.name} is being terminated",
        keep=[TERMINATE_JOB],
    )
    return _start_job(actor, constellation, TERMINATE_JOB)


def start_refresh_access(actor: Actor, constellation: Constellation) -> Job:
    """Start the job that pushes who may come in: the VPN's revocations to the router, the
    team members' SSH keys to the field computers."""
    return _start_job(actor, constellation, "constellation.refresh_access")


def launching(constellation: Constellation) -> None:
    """Mark a constellation as being launched, clearing any earlier error."""
    constellation.state, constellation.error = ConstellationState.LAUNCHING, None
    constellation.error_code = None


def failed(constellation: Constellation, error: str, code: str | None = None) -> bool:
    """Mark a constellation's launch as failed, with why (and its code, cloudsim.error_codes);
    never one being terminated (a terminate wins over the launch it stopped). Return whether it
    was marked."""
    if constellation.state in GONE:
        return False
    constellation.state = ConstellationState.ERROR
    constellation.error, constellation.error_code = error, code
    return True


def ready(constellation: Constellation) -> None:
    """Mark a constellation and all its machines ready."""
    constellation.state = ConstellationState.READY
    for machine in constellation.machines:
        machine.state = MachineState.READY


def machine_creating(machine: Machine) -> None:
    """Mark a machine as being created at the provider."""
    machine.state = MachineState.CREATING


def machine_running(machine: Machine) -> None:
    """Mark a machine as running at the provider (not yet configured)."""
    machine.state = MachineState.RUNNING


def terminating(constellation: Constellation) -> None:
    """Mark a constellation and all its machines as being terminated."""
    constellation.state = ConstellationState.TERMINATING
    for machine in constellation.machines:
        machine.state = MachineState.TERMINATING


def terminate_incomplete(constellation: Constellation, reason: str) -> None:
    """Mark a constellation whose terminate left a machine not cleaned, with which and why."""
    constellation.state = ConstellationState.TERMINATE_INCOMPLETE
    constellation.error = f"{TERMINATE_INCOMPLETE}{reason}"


def terminated(constellation: Constellation) -> None:
    """Mark a constellation and all its machines terminated."""
    for machine in constellation.machines:
        machine.state = MachineState.TERMINATED
    constellation.state = ConstellationState.TERMINATED
    if constellation.error and constellation.error.startswith(TERMINATE_INCOMPLETE):
        constellation.error = None  # the retry cleaned what the earlier terminate could not
