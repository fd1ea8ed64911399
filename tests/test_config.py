"""Configuration: defaults, generated instance keys, clear errors."""

from __future__ import annotations

import stat
from pathlib import Path

import pytest

from cloudsim.config import Config, ConfigError


def test_defaults_generate_private_keys_once(tmp_path: Path) -> None:
    env = {"CLOUDSIM_INSTANCE_DIR": str(tmp_path)}
    first = Config.from_env(env)
    assert first.database_url == f"sqlite:///{tmp_path / 'cloudsim.db'}"
    assert first.effective_redis_url == "redis://127.0.0.1:6390/0"
    for name in ("secret.key", "encryption.key"):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == 0o600
    again = Config.from_env(env)
    assert again.secret_key == first.secret_key
    assert again.encryption_keys == first.encryption_keys
    assert first.secret_key not in repr(first) and first.encryption_keys[0] not in repr(first)


@pytest.mark.parametrize(
    ("name", "value", "message"),
    [
        ("CLOUDSIM_WEB_WORKERS", "two", "CLOUDSIM_WEB_WORKERS must be a whole number"),
        ("CLOUDSIM_SECURE_COOKIES", "maybe", "CLOUDSIM_SECURE_COOKIES"),
        ("CLOUDSIM_ENCRYPTION_KEYS", "not-a-key", "malformed Fernet key"),
        ("CLOUDSIM_LOG_FORMAT", "xml", "CLOUDSIM_LOG_FORMAT must be one of text, json"),
        ("CLOUDSIM_METRICS_NETWORKS", "10.0.0.0/8,nowhere", "'nowhere' is not a network"),
    ],
)
def test_bad_values_are_named(tmp_path: Path, name: str, value: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        Config.from_env({"CLOUDSIM_INSTANCE_DIR": str(tmp_path), name: value})


# The configuration page is generated from SETTINGS: tests/docs/test_site.py checks it.
