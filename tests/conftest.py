"""Fixtures shared by the whole suite: private Redis and PostgreSQL, apps, people, clients."""

from __future__ import annotations

import contextvars
import itertools
import logging
import re
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

import pytest
import redis
from cryptography.fernet import Fernet
from flask import Flask, has_app_context
from flask.testing import FlaskClient
from moto.server import ThreadedMotoServer

from cloudsim.app import create_app
from cloudsim.auth.policy import SYSTEM
from cloudsim.auth.tokens import issue_token
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.models import Role, Team, User
from cloudsim.people import service
from tests.support.servers import MotoEndpoint, PostgresServer, RedisServer

PASSWORD = "correct horse battery"
_names = itertools.count(1)
T = TypeVar("T")


@pytest.fixture(scope="session")
def redis_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RedisServer]:
    server = RedisServer(tmp_path_factory.mktemp("redis"))
    yield server
    server.stop()


@pytest.fixture(scope="session")
def postgres_server() -> Iterator[PostgresServer]:
    server = PostgresServer()
    yield server
    server.stop()


@pytest.fixture(scope="session")
def moto_endpoint() -> Iterator[MotoEndpoint]:
    """moto's EC2 server, in-process on a free loopback port, for the whole session."""
    # moto's request log is noise in test output; failures surface as EC2 errors instead.
    logging.getLogger("werkzeug").setLevel(logging.ERROR)
    server = ThreadedMotoServer(ip_address="127.0.0.1", port=0, verbose=False)
    server.start()
    host, port = server.get_host_and_port()
    yield MotoEndpoint(host, port)
    server.stop()


@pytest.fixture(scope="session")
def encryption_key() -> str:
    return Fernet.generate_key().decode()


@pytest.fixture(scope="session")
def wheelhouse_cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The machines' wheelhouses and CloudSim's bundle, shared by every instance of the session.

    A launch builds them into its instance's `wheelhouse/` once per version of the source
    and reuses them afterwards (pip: ~20 s for drcsim's and csrouter's wheels, ~30 s for the
    bundle on the 2-core machine): the session's first launch builds them, later ones take
    the cache, as a long-lived instance's launches do.
    """
    return tmp_path_factory.mktemp("wheelhouse")


@pytest.fixture
def make_config(
    tmp_path: Path, redis_server: RedisServer, encryption_key: str, wheelhouse_cache: Path
) -> Callable[..., Config]:
    """Build a test Config: its own instance folder (sharing the session's wheelhouse cache),
    the session's Redis (flushed)."""

    def build(database_url: str | None = None, **overrides: object) -> Config:
        url = redis_server.url(0)
        redis.Redis.from_url(url).flushdb()
        env = {
            "CLOUDSIM_INSTANCE_DIR": str(tmp_path / "instance"),
            "CLOUDSIM_REDIS_URL": url,
            "CLOUDSIM_ENCRYPTION_KEYS": encryption_key,
            "CLOUDSIM_SECRET_KEY": "test-secret-key",
            "CLOUDSIM_LOG_LEVEL": "WARNING",
            # Cheap hashes keep the suite fast; production keeps Argon2id's strong defaults.
            "CLOUDSIM_ARGON2_TIME_COST": "1",
            "CLOUDSIM_ARGON2_MEMORY_KIB": "1024",
        }
        if database_url:
            env["CLOUDSIM_DATABASE_URL"] = database_url
        config = Config.from_env(env, testing=True, **overrides)
        cache = config.instance_dir / "wheelhouse"
        if not cache.exists():
            cache.symlink_to(wheelhouse_cache, target_is_directory=True)
        return config

    return build


class IsolatedClient(FlaskClient):
    """A test client whose requests never share the test's app context (nor its `g`, nor its
    database session), exactly as in production where every request gets its own."""

    def open(self, *args: Any, **kwargs: Any) -> Any:
        # What the test did so far is its own finished transaction (services only flush): a
        # request, in its own session, must see it, and SQLite must not be left write-locked.
        if has_app_context():
            db.session.commit()
        return contextvars.Context().run(super().open, *args, **kwargs)


@contextmanager
def running_app(config: Config) -> Iterator[Flask]:
    """Create the app and its tables, and drop them afterwards."""
    app = create_app(config)
    app.test_client_class = IsolatedClient
    # An in-process worker (celery's start_worker) stops only once its wait for a message
    # returns: 0.1 s instead of kombu's 1 s takes ~1 s off every test that starts one.
    celery = app.extensions["celery"]
    celery.conf.broker_transport_options = {
        **celery.conf.broker_transport_options,
        "polling_interval": 0.1,
    }
    with app.app_context():
        db.create_all()
        yield app
        db.session.remove()
        db.drop_all()
        db.engine.dispose()


@pytest.fixture
def app(make_config: Callable[..., Config]) -> Iterator[Flask]:
    """An app on a fresh SQLite database, inside its app context."""
    with running_app(make_config()) as app:
        yield app


@pytest.fixture(params=["sqlite", "postgres"])
def any_db_app(
    request: pytest.FixtureRequest, make_config: Callable[..., Config]
) -> Iterator[Flask]:
    """The same test on SQLite and on the private PostgreSQL."""
    url = None
    if request.param == "postgres":
        server: PostgresServer = request.getfixturevalue("postgres_server")
        url = server.create_database(f"cloudsim_{next(_names)}")
    with running_app(make_config(url)) as app:
        yield app


@pytest.fixture
def team_a(app: Flask) -> Team:
    return _committed(service.create_team(SYSTEM, "Team A"))


@pytest.fixture
def team_b(app: Flask) -> Team:
    return _committed(service.create_team(SYSTEM, "Team B"))


def _committed(row: T) -> T:
    """Commit the test's setup, as the request or command that made it would."""
    db.session.commit()
    return row


def make_user(role: Role, team: Team | None = None, email: str | None = None) -> User:
    """Create a user with the shared test password."""
    email = email or f"{role.value}{next(_names)}@example.org"
    return _committed(
        service.create_user(
            SYSTEM, email=email, role=role, team_id=team.id if team else None, password=PASSWORD
        ).user
    )


@pytest.fixture
def people(app: Flask, team_a: Team, team_b: Team) -> dict[str, User | None]:
    """One person of each kind the authorization rules distinguish."""
    return {
        "anon": None,
        "user_a": make_user(Role.USER, team_a),
        "user_b": make_user(Role.USER, team_b),
        "officer": make_user(Role.OFFICER),
        "admin": make_user(Role.ADMIN),
    }


@pytest.fixture
def client(app: Flask) -> FlaskClient:
    return app.test_client()


def csrf_token(html: str) -> str:
    """Return the CSRF token of the first form in a page ("" when the app has CSRF off)."""
    match = re.search(r'name="csrf_token" type="hidden" value="([^"]+)"', html)
    return match.group(1) if match else ""


def log_in(client: FlaskClient, user: User) -> None:
    """Log a test client in through the real login form, CSRF token included."""
    token = csrf_token(client.get("/login").get_data(as_text=True))
    data = {"email": user.email, "password": PASSWORD, "csrf_token": token}
    response = client.post("/login", data=data)
    assert response.status_code == 302, response.get_data(as_text=True)


def token_for(user: User) -> dict[str, str]:
    """Return API headers carrying a fresh token of the user."""
    return {"Authorization": f"Bearer {issue_token(user, 'tests').plaintext}"}
