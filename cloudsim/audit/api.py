"""The audit trail."""

from __future__ import annotations

from typing import Any

from flask.views import MethodView

from cloudsim.api.common import Blueprint, SelectPage, caller_with
from cloudsim.audit.schemas import AuditEventSchema, AuditQuerySchema
from cloudsim.audit.service import visible_events
from cloudsim.models import Role

blp = Blueprint("api_audit", __name__, description="Who did what")


@blp.route("/audit")
class Audit(MethodView):
    @blp.arguments(AuditQuerySchema, location="query")
    @blp.response(200, AuditEventSchema(many=True))
    @blp.paginate(SelectPage, page_size=100, max_page_size=1000)
    def get(self, query: dict[str, Any]) -> Any:
        """List audit events, newest first (officers and admins)."""
        return visible_events(caller_with(Role.OFFICER, "read the audit trail"), **query)
