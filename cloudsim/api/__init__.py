"""The JSON REST API shell under /api/v1: the OpenAPI description; features add their blueprints."""

from __future__ import annotations

from flask import Flask, request
from flask_smorest import Api, Blueprint

from cloudsim import __version__
from cloudsim.extensions import csrf
from cloudsim.web.inputs import IdConverter, id_param_schema

API_PREFIX = "/api/v1"
PUBLIC_PATHS = {f"{API_PREFIX}/openapi.json"}
# paths whose callers are not users: their blueprint checks its own credential (the portal's
# ingest takes team instances' upload tokens)
OWN_AUTH_PREFIXES: set[str] = set()


def init_api(app: Flask) -> Api:
    """Create the API; it describes every blueprint at /api/v1/openapi.json."""
    app.config.update(
        API_TITLE="CloudSim API",
        API_VERSION=__version__,  # the OpenAPI info.version: this CloudSim's release
        OPENAPI_VERSION="3.0.3",
        OPENAPI_URL_PREFIX=API_PREFIX,
        OPENAPI_JSON_PATH="openapi.json",
        API_SPEC_OPTIONS={
            "info": {
                "description": "Everything the web pages do, for scripts. Authenticate with "
                "'Authorization: Bearer <token>'; create tokens on your account page.",
            },
            "components": {
                "securitySchemes": {
                    "bearerAuth": {"type": "http", "scheme": "bearer"},
                    "uploadToken": {
                        "type": "http",
                        "scheme": "bearer",
                        "description": "a team instance's upload token (cspu_...), which its "
                        "master hands it in the desired state",
                    },
                }
            },
            "security": [{"bearerAuth": []}],
        },
    )
    api = Api(app)
    app.extensions["cloudsim.api"] = api
    api.register_converter(IdConverter, id_param_schema)
    return api


def bearer_token() -> str:
    """Return the request's bearer token ('' when it sends none)."""
    scheme, _, token = request.headers.get("Authorization", "").partition(" ")
    return token.strip() if scheme.lower() == "bearer" else ""


def unauthenticated(message: str) -> tuple[dict[str, object], int]:
    """Return the API's answer to a request without a valid credential."""
    return {"code": 401, "message": message}, 401


def register_api(app: Flask, blueprint: Blueprint) -> None:
    """Serve a feature's API blueprint under /api/v1 (token-authenticated, so no CSRF)."""
    csrf.exempt(blueprint)
    app.extensions["cloudsim.api"].register_blueprint(blueprint, url_prefix=API_PREFIX)
