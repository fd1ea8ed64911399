"""Constellations and their machines."""

from __future__ import annotations

from typing import Any

from flask.views import MethodView
from flask_smorest import Blueprint
from sqlalchemy import select

from cloudsim.api.common import SelectPage, caller
from cloudsim.api.schemas import ConstellationSchema
from cloudsim.models import Constellation, Role

blp = Blueprint("api_constellations", __name__, description="Constellations and machines")


@blp.route("/constellations")
class Constellations(MethodView):
    @blp.response(200, ConstellationSchema(many=True))
    @blp.paginate(SelectPage, page_size=50, max_page_size=500)
    def get(self) -> Any:
        """List constellations (a team user: their team's only)."""
        user = caller()
        query = select(Constellation).order_by(Constellation.id)
        if not user.has_role(Role.OFFICER):
            query = query.where(Constellation.team_id == user.team_id)
        return query
