"""The API's bearer-token authentication, and the caller's own account and API tokens."""

from __future__ import annotations

from typing import Any

from flask import Flask, g, request
from flask.typing import ResponseReturnValue
from flask.views import MethodView

from cloudsim.api import (
    API_PREFIX,
    OWN_AUTH_PREFIXES,
    PUBLIC_PATHS,
    bearer_token,
    unauthenticated,
)
from cloudsim.api.common import Blueprint, caller, columns
from cloudsim.auth import ssh_keys
from cloudsim.auth.master import refuse_until_current
from cloudsim.auth.schemas import (
    GeneratedSshKeySchema,
    IssuedTokenSchema,
    SshKeySchema,
    TokenSchema,
)
from cloudsim.auth.tokens import issue_token, revoke_token, user_for_token
from cloudsim.errors import InvalidInput
from cloudsim.people.schemas import UserSchema

blp = Blueprint("api_account", __name__, description="The caller's account and API tokens")


def init_bearer_auth(app: Flask) -> None:
    """Make every API request (but the OpenAPI description) name its user by a bearer token."""

    @app.before_request
    def authenticate_api() -> ResponseReturnValue | None:
        if not request.path.startswith(API_PREFIX + "/") or request.path in PUBLIC_PATHS:
            return None
        if any(request.path.startswith(prefix) for prefix in OWN_AUTH_PREFIXES):
            return None
        user = user_for_token(bearer_token())
        if user is None:
            return unauthenticated("authentication required: send 'Authorization: Bearer <token>'")
        refuse_until_current(user)  # a restarted team instance: the master's accounts first
        g.api_user = user
        return None


@blp.route("/me")
class Me(MethodView):
    @blp.response(200, UserSchema)
    def get(self) -> Any:
        """Return the caller's account."""
        return caller()


@blp.route("/tokens")
class Tokens(MethodView):
    @blp.response(200, TokenSchema(many=True))
    def get(self) -> Any:
        """List the caller's tokens (never their values)."""
        return caller().tokens

    @blp.arguments(TokenSchema)
    @blp.response(201, IssuedTokenSchema)
    def post(self, data: dict[str, Any]) -> Any:
        """Create a token; its value is in this answer only."""
        issued = issue_token(caller(), data["name"])
        return {**columns(issued.token), "token": issued.plaintext}


@blp.route("/tokens/<int:token_id>")
class TokenById(MethodView):
    @blp.response(204)
    def delete(self, token_id: int) -> None:
        """Revoke one of the caller's tokens."""
        revoke_token(caller(), token_id)


@blp.route("/me/ssh-keys")
class SshKeys(MethodView):
    @blp.response(200, SshKeySchema(many=True))
    def get(self) -> Any:
        """List the caller's SSH public keys with their fingerprints."""
        return ssh_keys.list_keys(caller())

    @blp.arguments(SshKeySchema)
    @blp.response(201, GeneratedSshKeySchema)
    def post(self, data: dict[str, Any]) -> Any:
        """Add a public key (`public_key`), or `generate` one: its private key is answered once.

        The keys of a team's members log into `team` on its field computers within seconds.
        """
        if data["generate"]:
            if data["public_key"]:
                raise InvalidInput("give a public_key or ask to generate one, not both")
            made = ssh_keys.generate_key(caller(), data["name"])
            return {**columns(made.key), "private_key": made.private_key}
        if not data["public_key"]:
            raise InvalidInput("public_key is required (or generate: true)")
        return ssh_keys.add_key(caller(), data["public_key"], data["name"])


@blp.route("/me/ssh-keys/<int:key_id>")
class SshKeyById(MethodView):
    @blp.response(204)
    def delete(self, key_id: int) -> None:
        """Remove one of the caller's keys; it stops working on the field computers at once."""
        ssh_keys.delete_key(caller(), key_id)
