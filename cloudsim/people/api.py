"""Teams and users."""

from __future__ import annotations

from typing import Any

from flask.views import MethodView

from cloudsim.api.common import Blueprint, SelectPage, caller, caller_with, columns
from cloudsim.models import Role
from cloudsim.people import service
from cloudsim.people.schemas import (
    TeamSchema,
    UserCreatedSchema,
    UserCreateSchema,
    UserSchema,
    UserUpdateSchema,
)

blp = Blueprint("api_people", __name__, description="Teams and users")


@blp.route("/teams")
class Teams(MethodView):
    @blp.response(200, TeamSchema(many=True))
    def get(self) -> Any:
        """List the teams the caller may see (a team user: their own)."""
        return service.visible_teams(caller())

    @blp.arguments(TeamSchema)
    @blp.response(201, TeamSchema)
    def post(self, data: dict[str, Any]) -> Any:
        """Create a team (officers and admins)."""
        return service.create_team(caller(), data["name"])


@blp.route("/teams/<int:team_id>")
class TeamById(MethodView):
    @blp.response(200, TeamSchema)
    def get(self, team_id: int) -> Any:
        """Return a team."""
        return service.get_team(caller(), team_id)

    @blp.arguments(TeamSchema)
    @blp.response(200, TeamSchema)
    def patch(self, data: dict[str, Any], team_id: int) -> Any:
        """Rename a team (officers and admins)."""
        return service.rename_team(caller(), team_id, data["name"])

    @blp.response(204)
    def delete(self, team_id: int) -> None:
        """Delete a team without members or live constellations (officers and admins)."""
        service.delete_team(caller(), team_id)


@blp.route("/users")
class Users(MethodView):
    @blp.response(200, UserSchema(many=True))
    @blp.paginate(SelectPage, page_size=100, max_page_size=1000)
    def get(self) -> Any:
        """List users by e-mail (officers and admins)."""
        return service.users_query(caller_with(Role.OFFICER, "list users"))

    @blp.arguments(UserCreateSchema)
    @blp.response(201, UserCreatedSchema)
    def post(self, data: dict[str, Any]) -> Any:
        """Create a user; without a password CloudSim generates one and returns it once."""
        created = service.create_user(caller(), **data)
        return {**columns(created.user), "generated_password": created.generated_password}


@blp.route("/users/<int:user_id>")
class UserById(MethodView):
    @blp.response(200, UserSchema)
    def get(self, user_id: int) -> Any:
        """Return a user (officers and admins; anyone: themselves)."""
        return service.get_user(caller(), user_id)

    @blp.arguments(UserUpdateSchema)
    @blp.response(200, UserSchema)
    def patch(self, data: dict[str, Any], user_id: int) -> Any:
        """Change a user's name, role, team, active flag or password."""
        return service.update_user(caller(), user_id, **data)

    @blp.response(204)
    def delete(self, user_id: int) -> None:
        """Delete a user."""
        service.delete_user(caller(), user_id)
