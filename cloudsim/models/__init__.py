"""CloudSim's data model."""

from cloudsim.models.audit import AuditEvent
from cloudsim.models.base import Base, utcnow
from cloudsim.models.competition import (
    Artifact,
    Run,
    RunState,
    ScoreEvent,
    Task,
    Verification,
)
from cloudsim.models.jobs import Job, JobState
from cloudsim.models.machines import Constellation, ConstellationState, Machine, MachineState
from cloudsim.models.notifications import EmailOptOut, RunNotice, Webhook, WebhookDelivery
from cloudsim.models.people import ApiToken, LoginSession, Role, SshKey, Team, User
from cloudsim.models.portal import PortalRefusal, PortalUpload, UploadState
from cloudsim.models.seasons import Phase
from cloudsim.models.secrets import Secret, SecretKind
from cloudsim.models.team_instances import InstanceState, TeamInstance
from cloudsim.models.worlds import World

__all__ = [
    "ApiToken",
    "Artifact",
    "AuditEvent",
    "Base",
    "Constellation",
    "ConstellationState",
    "EmailOptOut",
    "InstanceState",
    "Job",
    "JobState",
    "LoginSession",
    "Machine",
    "MachineState",
    "Phase",
    "PortalRefusal",
    "PortalUpload",
    "Role",
    "Run",
    "RunNotice",
    "RunState",
    "ScoreEvent",
    "Secret",
    "SecretKind",
    "SshKey",
    "Task",
    "Team",
    "TeamInstance",
    "UploadState",
    "User",
    "Verification",
    "Webhook",
    "WebhookDelivery",
    "World",
    "utcnow",
]
