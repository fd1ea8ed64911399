"""Webhooks and their deliveries in the API (admins)."""

from __future__ import annotations

from typing import Any

from flask.views import MethodView
from marshmallow import Schema, fields, validate

from cloudsim.api.common import Blueprint, SelectPage, caller_with, columns
from cloudsim.audit.service import record
from cloudsim.models import Role
from cloudsim.notifications import service

blp = Blueprint("api_notifications", __name__, description="Run e-mails and webhooks")


class NewWebhookSchema(Schema):
    url = fields.Str(
        required=True,
        validate=validate.Length(max=500),
        metadata={"description": "http(s) URL every run event is POSTed to"},
    )
    secret = fields.Str(
        load_default=None,
        validate=validate.Length(min=16, max=200),
        metadata={"description": "signing secret; omitted: one is generated (answered once)"},
    )


class WebhookSchema(Schema):
    id = fields.Int()
    url = fields.Str()
    created_at = fields.DateTime()


class AddedWebhookSchema(WebhookSchema):
    secret = fields.Str(metadata={"description": "the signing secret, in this answer only"})


class AttemptSchema(Schema):
    at = fields.Str()
    status_code = fields.Int(allow_none=True)
    error = fields.Str(allow_none=True)


class DeliverySchema(Schema):
    id = fields.Int()
    webhook_id = fields.Int(allow_none=True)
    event = fields.Function(lambda d: f"run.{d.event}")
    run_id = fields.Int()
    url = fields.Str()
    status_code = fields.Int(allow_none=True)
    attempts = fields.Int()
    last_error = fields.Str(allow_none=True)
    history = fields.List(fields.Nested(AttemptSchema))
    created_at = fields.DateTime()
    attempted_at = fields.DateTime(allow_none=True)
    delivered_at = fields.DateTime(allow_none=True)


@blp.route("/webhooks")
class Webhooks(MethodView):
    @blp.response(200, WebhookSchema(many=True))
    def get(self) -> Any:
        """List the webhooks (admins; never their secrets)."""
        return service.webhooks(caller_with(Role.ADMIN, "list webhooks"))

    @blp.arguments(NewWebhookSchema)
    @blp.response(201, AddedWebhookSchema)
    def post(self, data: dict[str, Any]) -> Any:
        """Add a webhook (admins); its secret is in this answer only."""
        actor = caller_with(Role.ADMIN, "add webhooks")
        hook, secret = service.add_webhook(actor, data["url"], data["secret"])
        record("webhook.add", actor, target_type="webhook", target_id=hook.id)
        return {**columns(hook), "secret": secret}


@blp.route("/webhooks/<int:webhook_id>")
class WebhookById(MethodView):
    @blp.response(204)
    def delete(self, webhook_id: int) -> None:
        """Remove a webhook (admins); its deliveries stay listed."""
        actor = caller_with(Role.ADMIN, "remove webhooks")
        service.remove_webhook(actor, webhook_id)
        record("webhook.remove", actor, target_type="webhook", target_id=webhook_id)


@blp.route("/webhook-deliveries")
class Deliveries(MethodView):
    @blp.response(200, DeliverySchema(many=True))
    @blp.paginate(SelectPage, page_size=50, max_page_size=500)
    def get(self) -> Any:
        """List webhook deliveries, newest first, each with its attempts (admins)."""
        return service.deliveries(caller_with(Role.ADMIN, "list webhook deliveries"))
