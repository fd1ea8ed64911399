"""The application factory: everything is built here, nothing at import time."""

from __future__ import annotations

import logging
import os
from datetime import timedelta
from typing import Any

from flask import Flask
from sqlalchemy import event

import templates
from cloudsim.auth.passwords import Passwords
from cloudsim.config import Config
from cloudsim.crypto import Keyring
from cloudsim.extensions import csrf, db, limiter, login_manager
from cloudsim.web.inputs import init_inputs
from cloudsim.web.security import init_security


def create_app(config: Config | None = None) -> Flask:
    """Build the CloudSim web app (and its Celery app) from a Config or the environment."""
    config = config or Config.from_env()
    web_templates = templates.folder("web")
    app = Flask(
        "cloudsim",
        template_folder=str(web_templates),
        static_folder=str(web_templates / "static"),
        instance_path=str(config.instance_dir),
    )
    app.config.update(
        CLOUDSIM=config,
        SECRET_KEY=config.secret_key,
        TESTING=config.testing,
        SQLALCHEMY_DATABASE_URI=config.database_url,
        SQLALCHEMY_ENGINE_OPTIONS=_engine_options(config.database_url),
        SESSION_COOKIE_HTTPONLY=True,
        SESSION_COOKIE_SAMESITE="Lax",
        SESSION_COOKIE_SECURE=config.secure_cookies,
        REMEMBER_COOKIE_HTTPONLY=True,
        REMEMBER_COOKIE_SAMESITE="Lax",
        REMEMBER_COOKIE_SECURE=config.secure_cookies,
        PERMANENT_SESSION_LIFETIME=timedelta(hours=config.session_hours),
        WTF_CSRF_TIME_LIMIT=None,  # the token lives as long as the session
        RATELIMIT_STORAGE_URI=config.effective_redis_url,
        RATELIMIT_HEADERS_ENABLED=True,
    )
    init_inputs(app)  # before any route: their <int:...> converters are bound when added
    init_security(app, config)
    logging.getLogger("cloudsim").setLevel(config.log_level)
    app.extensions["cloudsim.keyring"] = Keyring(config.encryption_keys)
    app.extensions["cloudsim.passwords"] = Passwords(
        config.argon2_time_cost, config.argon2_memory_kib
    )

    db.init_app(app)
    if config.database_url.startswith("sqlite"):
        with app.app_context():
            _private_database_file(db.engine.url.database)
            event.listen(db.engine, "connect", _sqlite_pragmas)
    csrf.init_app(app)
    limiter.init_app(app)
    login_manager.init_app(app)

    from cloudsim.api import init_api
    from cloudsim.features import features
    from cloudsim.jobs.queue import celery_init_app
    from cloudsim.web import register_web

    celery_init_app(app, config)
    init_api(app)
    for feature in features():
        feature.init_app(app)
    register_web(app)  # after the API: its error pages answer JSON under /api/ too
    return app


def _engine_options(url: str) -> dict[str, Any]:
    if url.startswith("sqlite"):
        return {"connect_args": {"timeout": 30}}
    return {"pool_pre_ping": True}


def _private_database_file(path: str | None) -> None:
    """Create the SQLite file readable by its owner only (its -wal and -shm files follow it)."""
    if not path or path == ":memory:":
        return
    os.close(os.open(path, os.O_RDWR | os.O_CREAT, 0o600))
    os.chmod(path, 0o600)


def _sqlite_pragmas(dbapi_connection: Any, _record: Any) -> None:
    """Make SQLite safe for several processes: WAL, a busy timeout, enforced foreign keys."""
    cursor = dbapi_connection.cursor()
    cursor.execute("PRAGMA journal_mode=WAL")
    cursor.execute("PRAGMA busy_timeout=30000")
    cursor.execute("PRAGMA foreign_keys=ON")
    cursor.close()
