"""The `cloudsim` command: help, migrations, teams and users, JSON output, one-line errors."""

from __future__ import annotations

import json
import subprocess
from collections.abc import Callable
from pathlib import Path

import pytest
from click.testing import CliRunner, Result

from cloudsim.cli import main
from tests.support.servers import RedisServer


@pytest.fixture
def run(tmp_path: Path, redis_server: RedisServer, encryption_key: str) -> Callable[..., Result]:
    env = {
        "CLOUDSIM_INSTANCE_DIR": str(tmp_path / "instance"),
        "CLOUDSIM_REDIS_URL": redis_server.url(0),
        "CLOUDSIM_ENCRYPTION_KEYS": encryption_key,
        "CLOUDSIM_ARGON2_TIME_COST": "1",
        "CLOUDSIM_ARGON2_MEMORY_KIB": "1024",
    }

    def invoke(*args: str, stdin: str | None = None) -> Result:
        return CliRunner().invoke(main, list(args), env=env, input=stdin)

    assert invoke("db", "upgrade").exit_code == 0
    return invoke


def test_help_lists_the_commands() -> None:
    out = subprocess.run(
        [str(Path(".venv/bin/cloudsim").resolve()), "--help"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    for command in ("up", "db", "team", "user"):
        assert f"  {command} " in out


def test_help_imports_no_command_and_no_engine() -> None:
    """`cloudsim --help` and `--version` load neither Flask, the models nor pybullet: the
    commands are listed from their table and imported only when one runs."""
    probe = (
        "import sys\n"
        "from cloudsim.cli import main\n"
        "try:\n"
        "    main(sys.argv[1:])\n"
        "except SystemExit:\n"
        "    pass\n"
        "heavy = sorted({m.split('.')[0] for m in sys.modules} & "
        "{'flask', 'sqlalchemy', 'celery', 'pybullet', 'drcsim', 'paramiko'})\n"
        "print('HEAVY', heavy)\n"
    )
    for args in (["--help"], ["--version"]):
        result = subprocess.run(
            [str(Path(".venv/bin/python").absolute()), "-W", "error", "-c", probe, *args],
            capture_output=True,
            text=True,
            check=True,
        )
        assert result.stdout.splitlines()[-1] == "HEAVY []", result.stdout
        assert result.stderr == ""
    version = subprocess.run(
        [str(Path(".venv/bin/python").absolute()), "-m", "cloudsim.cli", "--version"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    from importlib.metadata import version as installed

    assert version.strip() == f"cloudsim {installed('cloudsim')}"


def test_the_listed_help_is_each_commands_own() -> None:
    """The one-line help `cloudsim --help` shows without importing a command is the command's."""
    from click import Context

    assert main.lazy_commands, "the commands are registered lazily"
    for name, lazy in main.lazy_commands.items():
        command = lazy.load()
        assert command.name == name, name
        assert command.get_short_help_str(1000) == lazy.help, name
    listed = main.list_commands(Context(main))
    assert set(main.lazy_commands) <= set(listed)


def test_db_current_and_downgrade(run: Callable[..., Result]) -> None:
    from alembic.script import ScriptDirectory

    import migrations

    head = ScriptDirectory(str(migrations.folder())).get_current_head()
    assert run("db", "current").output.strip() == head
    assert "base" in run("db", "downgrade", "base").output
    assert "empty database" in run("db", "current").output


def test_teams_and_users_with_json_output(run: Callable[..., Result]) -> None:
    team = json.loads(run("team", "create", "Team Seven", "--json").output)
    assert team["name"] == "Team Seven" and team["id"] >= 1
    created = run("user", "create", "--email", "Pat@Example.org", "--team", "Team Seven", "--json")
    assert created.exit_code == 0, created.output
    user = json.loads(created.output)
    assert user["email"] == "pat@example.org" and user["team"] == "Team Seven"
    assert len(user["password"]) >= 16  # generated and shown this once
    officer = run(
        "user",
        "create",
        "--email",
        "o@example.org",
        "--role",
        "officer",
        "--password-stdin",
        "--json",
        stdin="a long enough password\n",
    )
    assert "password" not in json.loads(officer.output)
    listing = json.loads(run("user", "list", "--json").output)
    assert [u["email"] for u in listing] == ["o@example.org", "pat@example.org"]
    assert "Team Seven\t1 members" in run("team", "list").output


@pytest.mark.parametrize(
    ("args", "code", "message"),
    [
        (("team", "create", "   "), 1, "Error: team name must not be empty"),
        (
            ("user", "create", "--email", "x@example.org", "--team", "Nope"),
            1,
            "Error: no team named 'Nope'",
        ),
        (
            ("user", "create", "--email", "not-an-email", "--role", "admin"),
            1,
            "Error: invalid e-mail address",
        ),
        (("user", "create", "--email", "x@example.org"), 1, "must belong to a team"),
        (("user", "create", "--email", "x@example.org", "--role", "king"), 2, "Invalid value"),
        (("team", "frobnicate"), 2, "No such command"),
    ],
)
def test_bad_input_gives_one_line_and_nonzero_exit(
    run: Callable[..., Result], args: tuple[str, ...], code: int, message: str
) -> None:
    result = run(*args)
    assert result.exit_code == code
    assert message in result.output
    if code == 1:
        assert len(result.output.strip().splitlines()) == 1
    assert run("user", "list").output.strip() == "no users"


def test_duplicate_team_is_refused(run: Callable[..., Result]) -> None:
    run("team", "create", "Dup")
    result = run("team", "create", "dup")
    assert result.exit_code == 1 and "already exists" in result.output


def test_providers_are_configured_with_clear_errors(
    run: Callable[..., Result], tmp_path: Path
) -> None:
    from cloudsim.launched_constellations.keys import generate_keypair

    assert "ec2\tnot configured" in run("provider", "list").output
    bad = tmp_path / "bad.yaml"
    bad.write_text("- {name: s1, address: 10.9.0.5}\n")
    result = run("provider", "configure", "servers", "--inventory", str(bad))
    assert result.exit_code == 1 and "servers inventory:" in result.output
    key = generate_keypair("inventory").private
    good = tmp_path / "servers.yaml"
    entry = {
        "name": "s1",
        "address": "10.9.0.5",
        "private_ip": "10.9.0.5",
        "network": "rack",
        "cidr": "10.9.0.0/24",
        "private_key": key,
    }
    good.write_text(json.dumps([entry]))  # JSON is YAML
    result = run("provider", "configure", "servers", "--inventory", str(good))
    assert result.exit_code == 0, result.output
    assert "servers\tconfigured" in run("provider", "list").output
    ec2 = run(
        "provider",
        "configure",
        "ec2",
        "--region",
        "us-east-1",
        "--access-key",
        "AKID",
        "--secret-key-stdin",
        "--image",
        "ami-1",
        "--size",
        "gpu",
        stdin="s3cr3t\n",
    )
    assert ec2.exit_code == 2 and "'gpu' is not LOGICAL=TYPE" in ec2.output
    ec2 = run(
        "provider",
        "configure",
        "ec2",
        "--region",
        "us-east-1",
        "--access-key",
        "AKID",
        "--secret-key-stdin",
        "--image",
        "ami-1",
        "--size",
        "gpu=g4dn.xlarge",
        stdin="s3cr3t\n",
    )
    assert ec2.exit_code == 0 and "s3cr3t" not in ec2.output
    listed = json.loads(run("provider", "list", "--json").output)
    assert {p["name"]: p["configured"] for p in listed} == {
        "local": True,
        "ec2": True,
        "servers": True,
    }


def test_user_update_moves_promotes_and_disables(run: Callable[..., Result]) -> None:
    run("team", "create", "Red")
    run("team", "create", "Blue")
    run("user", "create", "--email", "pat@example.org", "--team", "Red")
    run("user", "create", "--email", "root@example.org", "--role", "admin")
    moved = run("user", "update", "pat@example.org", "--team", "Blue", "--name", "Pat", "--json")
    assert moved.exit_code == 0, moved.output
    assert json.loads(moved.output) | {"id": 0} == {
        "id": 0,
        "email": "pat@example.org",
        "name": "Pat",
        "role": "user",
        "team": "Blue",
        "active": True,
    }
    off = run("user", "update", "pat@example.org", "--inactive")
    assert off.output.strip() == "updated pat@example.org: user, Blue, disabled"
    up = run("user", "update", "pat@example.org", "--role", "officer", "--no-team", "--active")
    assert up.output.strip() == "updated pat@example.org: officer, no team, active"
    # The last admin stays one; a team user needs a team: one line, exit 1, nothing changed.
    for args, message in (
        (("root@example.org", "--role", "officer"), "at least one active admin"),
        (("root@example.org", "--inactive"), "at least one active admin"),
        (("pat@example.org", "--role", "user"), "must belong to a team"),
        (("nobody@example.org", "--inactive"), "no user 'nobody@example.org'"),
    ):
        result = run("user", "update", *args)
        assert result.exit_code == 1 and message in result.output, result.output
    listing = {u["email"]: u for u in json.loads(run("user", "list", "--json").output)}
    assert listing["root@example.org"]["role"] == "admin" and listing["root@example.org"]["active"]
    assert listing["pat@example.org"]["role"] == "officer"


def test_ssh_keys_of_a_user_are_added_listed_refused_and_removed(
    run: Callable[..., Result], tmp_path: Path
) -> None:
    from cryptography.hazmat.primitives import serialization
    from cryptography.hazmat.primitives.asymmetric import ed25519, rsa

    def public(key: object) -> str:
        return (
            key.public_key()
            .public_bytes(  # type: ignore[attr-defined, no-any-return]
                serialization.Encoding.OpenSSH, serialization.PublicFormat.OpenSSH
            )
            .decode()
        )

    assert run("team", "create", "Keys").exit_code == 0
    made = run("user", "create", "--email", "k@example.org", "--team", "Keys")
    assert made.exit_code == 0, made.output
    (tmp_path / "id.pub").write_text(public(ed25519.Ed25519PrivateKey.generate()) + " k@laptop\n")
    added = run("user", "ssh-key", "add", "k@example.org", str(tmp_path / "id.pub"))
    assert added.exit_code == 0 and "SHA256:" in added.output, added.output
    [key] = json.loads(run("user", "ssh-key", "list", "k@example.org", "--json").output)
    (tmp_path / "weak.pub").write_text(public(rsa.generate_private_key(65537, 2048)))
    refused = run("user", "ssh-key", "add", "k@example.org", str(tmp_path / "weak.pub"))
    assert refused.exit_code == 1 and "at least 3072" in refused.output
    generated = run("user", "ssh-key", "add", "k@example.org", "--generate")
    assert generated.exit_code == 0 and "BEGIN OPENSSH PRIVATE KEY" in generated.output
    assert run("user", "ssh-key", "remove", "k@example.org", str(key["id"])).exit_code == 0
    gone = run("user", "ssh-key", "remove", "k@example.org", str(key["id"]))
    assert gone.exit_code == 1 and f"SSH key {key['id']} not found" in gone.output
    huge = run("user", "ssh-key", "remove", "k@example.org", "99999999999")
    assert huge.exit_code == 2 and "Traceback" not in huge.output  # click's usage error
    listed = run("user", "ssh-key", "list", "k@example.org").output
    assert key["fingerprint"] not in listed and "made by CloudSim" in listed
