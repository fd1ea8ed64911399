"""The JSON REST API under /api/v1: token authentication, OpenAPI description, blueprints."""

from __future__ import annotations

from flask import Flask, g, request
from flask.typing import ResponseReturnValue
from flask_smorest import Api

from cloudsim.auth.tokens import user_for_token
from cloudsim.extensions import csrf

API_PREFIX = "/api/v1"
PUBLIC_PATHS = {f"{API_PREFIX}/openapi.json"}


def init_api(app: Flask) -> Api:
    """Register the API blueprints and serve their OpenAPI description at /api/v1/openapi.json."""
    app.config.update(
        API_TITLE="CloudSim API",
        API_VERSION="v1",
        OPENAPI_VERSION="3.0.3",
        OPENAPI_URL_PREFIX=API_PREFIX,
        OPENAPI_JSON_PATH="openapi.json",
        API_SPEC_OPTIONS={
            "info": {
                "description": "Everything the web pages do, for scripts. Authenticate with "
                "'Authorization: Bearer <token>'; create tokens on your account page.",
            },
            "components": {"securitySchemes": {"bearerAuth": {"type": "http", "scheme": "bearer"}}},
            "security": [{"bearerAuth": []}],
        },
    )
    api = Api(app)
    from cloudsim.api import account, audit, competition, constellations, jobs, people

    for module in (account, people, jobs, audit, constellations, competition):
        csrf.exempt(module.blp)
        api.register_blueprint(module.blp, url_prefix=API_PREFIX)

    @app.before_request
    def authenticate_api() -> ResponseReturnValue | None:
        if not request.path.startswith(API_PREFIX + "/") or request.path in PUBLIC_PATHS:
            return None
        scheme, _, token = request.headers.get("Authorization", "").partition(" ")
        user = user_for_token(token.strip()) if scheme.lower() == "bearer" else None
        if user is None:
            message = "authentication required: send 'Authorization: Bearer <token>'"
            return {"code": 401, "message": message}, 401
        g.api_user = user
        return None

    return api
