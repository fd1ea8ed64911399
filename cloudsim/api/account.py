"""The caller's own account and API tokens."""

from __future__ import annotations

from typing import Any

from flask.views import MethodView
from flask_smorest import Blueprint

from cloudsim.api.common import caller, columns
from cloudsim.api.schemas import IssuedTokenSchema, TokenSchema, UserSchema
from cloudsim.auth.tokens import issue_token, revoke_token

blp = Blueprint("api_account", __name__, description="The caller's account and API tokens")


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
