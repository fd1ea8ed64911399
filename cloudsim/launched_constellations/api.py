"""Constellations and their machines."""

from __future__ import annotations

from typing import Any

from flask import current_app
from flask.views import MethodView

from cloudsim.api.common import Blueprint, SelectPage, caller
from cloudsim.jobs.schemas import JobSchema
from cloudsim.launched_constellations import progress, service, vpn
from cloudsim.launched_constellations.capacity import visible_room
from cloudsim.launched_constellations.schemas import (
    CapacityQuerySchema,
    CapacitySchema,
    ConstellationSchema,
    ConstellationStatusSchema,
    ConstellationUpdateSchema,
    LaunchedSchema,
    LaunchSchema,
    VpnBundleQuerySchema,
)
from cloudsim.web.downloads import attachment

blp = Blueprint("api_constellations", __name__, description="Constellations and machines")


@blp.route("/constellations")
class Constellations(MethodView):
    @blp.response(200, ConstellationSchema(many=True))
    @blp.paginate(SelectPage, page_size=50, max_page_size=500)
    def get(self) -> Any:
        """List constellations (a team user: their team's only)."""
        return service.visible_constellations(caller())

    @blp.arguments(LaunchSchema)
    @blp.response(202, LaunchedSchema)
    def post(self, data: dict[str, Any]) -> Any:
        """Launch a constellation (admins); follow the returned job."""
        constellation, job = service.launch(caller(), **data)
        return {"constellation": constellation, "job": job}


@blp.route("/constellations/capacity")
class Capacity(MethodView):
    @blp.arguments(CapacityQuerySchema, location="query")
    @blp.response(200, CapacitySchema)
    def get(self, query: dict[str, Any]) -> Any:
        """Say how many more machines (and constellations of each kind) a provider can take
        (officers and admins); a launch beyond it is refused with 409."""
        found = visible_room(caller(), query["provider"], current_app.config["CLOUDSIM"])
        if found is None:
            return {"provider": query["provider"], "known": False, "kinds": {}}
        capacity = found.capacity
        return {
            "provider": found.provider,
            "known": True,
            "hosts": capacity.hosts,
            "networks": capacity.networks,
            "public_addresses": capacity.public,
            "limited_by": capacity.limited_by,
            "memory_mib": capacity.memory_mib,
            "host_memory_mib": capacity.host_memory_mib,
            "kinds": found.kinds,
        }


@blp.route("/constellations/<int:ref>")
class ConstellationById(MethodView):
    @blp.response(200, ConstellationStatusSchema)
    def get(self, ref: int) -> Any:
        """Return a constellation with its machines, their verification and when each was last
        heard from, and its latest job's step and since when."""
        return progress.detail(service.get_constellation(caller(), ref))

    @blp.arguments(ConstellationUpdateSchema)
    @blp.response(200, ConstellationSchema)
    def patch(self, data: dict[str, Any], ref: int) -> Any:
        """Let the team's members use sudo on the field computers, or not (officers)."""
        return service.set_team_sudo(caller(), ref, data["team_sudo"])

    @blp.response(202, JobSchema)
    def delete(self, ref: int) -> Any:
        """Terminate a constellation (admins); follow the returned job."""
        return service.terminate(caller(), ref)


@blp.route("/constellations/<int:ref>/retry")
class Retry(MethodView):
    @blp.response(202, JobSchema)
    def post(self, ref: int) -> Any:
        """Launch again a constellation in error, resuming what exists, or terminate again
        one in terminate_incomplete, cleaning the machines left (admins)."""
        return service.retry(caller(), ref)


@blp.route("/constellations/<int:ref>/ssh-bundle")
class SshBundle(MethodView):
    @blp.response(200, content_type="application/zip")
    def get(self, ref: int) -> Any:
        """Download the constellation's SSH key bundle (officers and admins)."""
        filename, data = service.ssh_bundle(caller(), ref)
        return attachment(data, filename, private=True)


@blp.route("/constellations/<int:ref>/vpn-bundle")
class VpnBundle(MethodView):
    @blp.arguments(VpnBundleQuerySchema, location="query")
    @blp.response(200, content_type="application/zip")
    def get(self, query: dict[str, Any], ref: int) -> Any:
        """Download a team user's VPN bundle: the caller's own, or (officers) user_id's."""
        constellation = service.get_constellation(caller(), ref)
        filename, data = vpn.vpn_bundle(caller(), constellation, query.get("user_id"))
        return attachment(data, filename, private=True)
