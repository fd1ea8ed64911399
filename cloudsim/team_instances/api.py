"""Team instances: the master's API, and each instance's own health endpoint."""

from __future__ import annotations

from typing import Any

from flask.views import MethodView

from cloudsim.api.common import Blueprint, SelectPage, caller, caller_with
from cloudsim.jobs.schemas import JobSchema
from cloudsim.models import Role
from cloudsim.team_instances import health, launch, service
from cloudsim.team_instances.apply import apply_desired_state
from cloudsim.team_instances.schemas import (
    AssignSchema,
    DeployedSchema,
    DeploySchema,
    DesiredStateSchema,
    HealthSchema,
    InstanceProviderSchema,
    LaunchThroughSchema,
    OutcomeSchema,
    SyncResultSchema,
    TeamInstanceSchema,
    TeamInstanceStatusSchema,
)

blp = Blueprint("api_team_instances", __name__, description="Team instances (master and instance)")


@blp.route("/team-instances")
class TeamInstances(MethodView):
    @blp.response(200, TeamInstanceSchema(many=True))
    @blp.paginate(SelectPage, page_size=50, max_page_size=500)
    def get(self) -> Any:
        """List the team instances this CloudSim deployed (admins)."""
        return service.visible_instances(caller())

    @blp.arguments(DeploySchema)
    @blp.response(202, DeployedSchema(many=True))
    def post(self, data: dict[str, Any]) -> Any:
        """Deploy a team's CloudSim, or `count` spares (admins); follow each returned job."""
        deployed = service.deploy(caller(), **data)
        return [{"instance": instance, "job": job} for instance, job in deployed]


@blp.route("/team-instances/<int:instance_id>")
class TeamInstanceById(MethodView):
    @blp.response(200, TeamInstanceStatusSchema)
    def get(self, instance_id: int) -> Any:
        """Return a team instance: state, health, when it was last heard from, last sync, and
        its latest job's step and since when (admins)."""
        return service.status(caller(), instance_id)

    @blp.arguments(AssignSchema)
    @blp.response(200, TeamInstanceSchema)
    def patch(self, data: dict[str, Any], instance_id: int) -> Any:
        """Assign a spare instance to a team (admins)."""
        return service.assign(caller(), instance_id, data["team_id"])

    @blp.response(202, JobSchema)
    def delete(self, instance_id: int) -> Any:
        """Terminate the instance's machines (admins); follow the returned job."""
        return service.terminate(caller(), instance_id)


@blp.route("/team-instances/<int:instance_id>/provider")
class InstanceProvider(MethodView):
    @blp.arguments(InstanceProviderSchema)
    @blp.response(200, TeamInstanceSchema)
    def put(self, data: dict[str, Any], instance_id: int) -> Any:
        """Keep (encrypted) the provider settings handed to the instance at launch (admins)."""
        return launch.set_provider_settings(
            caller(), instance_id, data["provider"], data["settings"]
        )


@blp.route("/team-instances/launch")
class LaunchThrough(MethodView):
    @blp.arguments(LaunchThroughSchema)
    @blp.response(200, OutcomeSchema(many=True))
    def post(self, data: dict[str, Any]) -> Any:
        """Launch each team's constellation through its instance (admins): who is ready,
        launching, or failed and why."""
        return launch.launch(caller(), data["kind"], data["provider"], data["instance_ids"])


@blp.route("/instance/health")
class InstanceHealth(MethodView):
    @blp.response(200, HealthSchema)
    def get(self) -> Any:
        """This CloudSim's version and whether its database, queue and worker are alive
        (admins: what a master polls)."""
        caller_with(Role.ADMIN, "read this instance's health")
        return health.report()


@blp.route("/instance/desired-state")
class DesiredState(MethodView):
    @blp.arguments(DesiredStateSchema)
    @blp.response(200, SyncResultSchema)
    def put(self, data: dict[str, Any]) -> Any:
        """Make this CloudSim what its master says (admins: the master); idempotent, answers
        what changed."""
        return apply_desired_state(caller_with(Role.ADMIN, "apply a desired state"), data)
