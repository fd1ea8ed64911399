"""The data model on SQLite and PostgreSQL: constraints, cascades, timestamps, encryption."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

import pytest
from flask import Flask
from sqlalchemy import select, text
from sqlalchemy.exc import IntegrityError

from cloudsim.auth.policy import SYSTEM
from cloudsim.crypto import DecryptionError, Keyring
from cloudsim.errors import NotFound
from cloudsim.extensions import db
from cloudsim.launched_constellations.service import get_constellation
from cloudsim.models import (
    Artifact,
    Constellation,
    Job,
    Machine,
    Role,
    Run,
    ScoreEvent,
    Secret,
    SecretKind,
    Task,
    Team,
    User,
)
from cloudsim.team_instances.service import get_instance
from tests.conftest import make_user

SSH_KEY = "\n".join(
    [
        "-----BEGIN OPENSSH PRIVATE KEY-----",
        "b3BlbnNzaC1rZXktdjEAAAAA",
        "-----END OPENSSH PRIVATE KEY-----",
    ]
)


def test_secret_is_encrypted_at_rest_and_hidden_from_repr(any_db_app: Flask) -> None:
    secret = Secret(
        kind=SecretKind.SSH_PRIVATE_KEY,
        owner_type="constellation",
        owner_id=1,
        name="ssh",
        value=SSH_KEY,
    )
    db.session.add(secret)
    db.session.commit()
    raw = db.session.execute(text("SELECT value FROM secrets")).scalar_one()
    assert SSH_KEY not in raw and "PRIVATE" not in raw
    db.session.expire_all()
    assert db.session.get(Secret, secret.id).value == SSH_KEY
    assert "PRIVATE" not in repr(secret) and "b3Bl" not in repr(secret)


def test_secret_names_are_unique_per_owner_even_for_the_installation(any_db_app: Flask) -> None:
    for _ in range(2):
        db.session.add(
            Secret(
                kind=SecretKind.CLOUD_CREDENTIALS,
                owner_type="installation",
                name="aws",
                value="AKIA...",
            )
        )
    with pytest.raises(IntegrityError):
        db.session.commit()
    db.session.rollback()


def test_keyring_rotation_reads_old_tokens_and_rejects_unknown_keys() -> None:
    from cryptography.fernet import Fernet

    old, new, other = (Fernet.generate_key().decode() for _ in range(3))
    token = Keyring((old,)).encrypt("vpn-key")
    rotated_ring = Keyring((new, old))
    assert rotated_ring.decrypt(token) == "vpn-key"
    assert Keyring((new,)).decrypt(rotated_ring.rotate(token)) == "vpn-key"
    with pytest.raises(DecryptionError):
        Keyring((other,)).decrypt(token)
    assert "key" not in repr(rotated_ring).lower().replace("keyring", "")


def test_timestamps_round_trip_as_aware_utc(any_db_app: Flask) -> None:
    team = Team(name="Tz")
    db.session.add(team)
    start = datetime(2013, 6, 17, 14, 0, tzinfo=UTC)
    task = Task(
        team=team,
        name="qual",
        world="vrc_task_1",
        window_start=start,
        window_stop=start + timedelta(hours=2),
        uplink_bits=115_200,
        downlink_bits=59_000_000_000,
    )
    db.session.add(task)
    db.session.commit()
    db.session.expire_all()
    loaded = db.session.get(Task, task.id)
    assert loaded.window_start == start and loaded.window_start.tzinfo is not None
    assert loaded.downlink_bits == 59_000_000_000  # needs a 64-bit column
    assert loaded.is_open(start + timedelta(minutes=5))
    assert not loaded.is_open(start + timedelta(hours=2))


def test_naive_timestamps_are_refused(any_db_app: Flask) -> None:
    db.session.add(Team(name="Naive", created_at=datetime(2020, 1, 1)))
    with pytest.raises(Exception, match="naive datetime"):
        db.session.commit()
    db.session.rollback()


def test_deleting_a_run_removes_its_artifacts_and_score_events(any_db_app: Flask) -> None:
    team = Team(name="Cascade")
    now = datetime.now(UTC)
    task = Task(
        team=team,
        name="t",
        world="vrc_task_2",
        window_start=now,
        window_stop=now + timedelta(hours=1),
        uplink_bits=1,
        downlink_bits=1,
    )
    run = Run(task=task, team=team)
    run.artifacts.append(
        Artifact(kind="score_log", filename="score.jsonl", location="/x", sha256="0" * 64)
    )
    run.score_events.append(ScoreEvent(checkpoint=1, points=1, sim_time=12.5, wall_time=now))
    db.session.add(run)
    db.session.commit()
    db.session.delete(run)
    db.session.commit()
    assert db.session.scalar(select(Artifact.id)) is None
    assert db.session.scalar(select(ScoreEvent.id)) is None


def test_constellation_machines_and_unique_machine_names(any_db_app: Flask) -> None:
    constellation = Constellation(name="vrc-team-7", kind="vrc", provider="local")
    for role in ("router", "sim", "fc1", "fc2"):
        constellation.machines.append(Machine(name=role, role=role, private_ip="10.0.0.1"))
    db.session.add(constellation)
    db.session.commit()
    assert [m.role for m in constellation.machines] == ["router", "sim", "fc1", "fc2"]
    db.session.add(Machine(constellation_id=constellation.id, name="sim", role="sim"))
    with pytest.raises(IntegrityError):
        db.session.commit()
    db.session.rollback()


def test_user_roles_order_and_emails_are_unique(any_db_app: Flask) -> None:
    assert Role.ADMIN.at_least(Role.OFFICER) and Role.OFFICER.at_least(Role.USER)
    assert not Role.USER.at_least(Role.OFFICER)
    admin = make_user(Role.ADMIN)
    assert admin.has_role(Role.OFFICER) and "password" not in repr(admin)
    db.session.add(User(email=admin.email, password_hash="x"))
    with pytest.raises(IntegrityError):
        db.session.commit()
    db.session.rollback()


def test_job_rows_keep_json_params(any_db_app: Flask) -> None:
    job = Job(
        id="00000000-0000-0000-0000-000000000001",
        kind="diagnostics",
        params={"machines": ["sim", "fc1"], "retries": 3},
    )
    db.session.add(job)
    db.session.commit()
    db.session.expire_all()
    assert db.session.get(Job, job.id).params == {"machines": ["sim", "fc1"], "retries": 3}


def test_a_ref_too_big_for_an_id_is_not_found_on_either_database(any_db_app: Flask) -> None:
    db.session.add(Constellation(name="kept", kind="simple", provider="local"))
    db.session.flush()
    assert get_constellation(SYSTEM, "kept").name == "kept"
    for get in (get_constellation, get_instance):
        with pytest.raises(NotFound):  # PostgreSQL refused the number with a DataError (a 500)
            get(SYSTEM, "99999999999")
