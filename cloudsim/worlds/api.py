"""Worlds API: list, read and update the world definitions (admins)."""

from __future__ import annotations

from typing import Any

from flask.views import MethodView

from cloudsim.api.common import Blueprint, caller_with
from cloudsim.models import Role
from cloudsim.worlds import service
from cloudsim.worlds.schemas import (
    WorldDocumentSchema,
    WorldSchema,
    WorldUpdatedSchema,
    WorldUploadSchema,
)

blp = Blueprint("api_worlds", __name__, description="World definitions (admins)")


@blp.route("/worlds")
class Worlds(MethodView):
    @blp.response(200, WorldSchema(many=True))
    def get(self) -> Any:
        """List the worlds runs are built from: version, digest, run configurations (admins)."""
        caller_with(Role.ADMIN, "read world definitions")
        return service.stored_worlds()


@blp.route("/worlds/<name>")
class WorldByName(MethodView):
    @blp.response(200, WorldDocumentSchema)
    def get(self, name: str) -> Any:
        """Return a world with its document (admins)."""
        return service.get_world(caller_with(Role.ADMIN, "read world definitions"), name)

    @blp.arguments(WorldUploadSchema)
    @blp.response(200, WorldUpdatedSchema)
    def put(self, data: dict[str, Any], name: str) -> Any:
        """Replace a world's document (admins): checked by the simulator's schema, a new
        version if it differs, propagated to every team instance."""
        actor = caller_with(Role.ADMIN, "update world definitions")
        return service.update_world(actor, data["document"], name)
