"""Security headers on every response: a strict CSP, no framing, no sniffing, no caching."""

from __future__ import annotations

from flask import Flask, Response, request
from flask_talisman import Talisman

from cloudsim.config import Config

# Scripts and styles come from /static only: the pages carry no inline script or style but the
# 3D viewer's import map, which carries the request's nonce.
CONTENT_SECURITY_POLICY = {
    "default-src": "'self'",
    "script-src": "'self'",
    "style-src": "'self'",
    "img-src": "'self' data:",
    "object-src": "'none'",
    "base-uri": "'none'",
    "form-action": "'self'",
    "frame-ancestors": "'none'",
}


def init_security(app: Flask, config: Config) -> None:
    """Send the security headers (flask-talisman) and keep dynamic answers out of caches."""
    Talisman(
        app,
        force_https=False,  # TLS ends at the reverse proxy, when there is one
        strict_transport_security=config.secure_cookies,
        session_cookie_secure=config.secure_cookies,
        content_security_policy=CONTENT_SECURITY_POLICY,
        content_security_policy_nonce_in=["script-src"],
        frame_options="DENY",
        referrer_policy="same-origin",
        x_content_type_options=True,
    )

    @app.after_request
    def no_store(response: Response) -> Response:
        # Pages show team data, new tokens and generated passwords: none may linger in a cache.
        if request.endpoint != "static":
            response.headers.setdefault("Cache-Control", "no-store")
        return response
