"""Providers in the API: an admin (or a master, on its team instance) stores a provider's
settings, encrypted, as `cloudsim provider configure` does; they are never sent back."""

from __future__ import annotations

from typing import Any

from flask.views import MethodView
from marshmallow import Schema, fields

from cloudsim.api.common import Blueprint, caller_with
from cloudsim.audit.service import record
from cloudsim.models import Role
from cloudsim.providers.service import configure_provider

blp = Blueprint("api_providers", __name__, description="Providers (settings stored encrypted)")


class ProviderSettingsSchema(Schema):
    settings = fields.Dict(
        required=True,
        metadata={
            "description": 'the provider\'s settings, e.g. servers: {"inventory": [...]}; '
            "stored encrypted, never answered"
        },
    )


class ProviderConfiguredSchema(Schema):
    name = fields.Str()
    configured = fields.Bool()


@blp.route("/providers/<name>")
class ProviderSettings(MethodView):
    @blp.arguments(ProviderSettingsSchema)
    @blp.response(200, ProviderConfiguredSchema)
    def put(self, data: dict[str, Any], name: str) -> Any:
        """Store a provider's settings, encrypted, replacing earlier ones (admins)."""
        actor = caller_with(Role.ADMIN, "configure providers")
        configure_provider(name, data["settings"])
        # which provider, never what: the settings hold credentials
        record("provider.configure", actor, target_type="provider", target_id=name)
        return {"name": name, "configured": True}
