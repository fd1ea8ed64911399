"""`cloudsim team` and `cloudsim user`: manage teams and users from the shell (as the system)."""

from __future__ import annotations

import sys

import click

from cloudsim.auth import ssh_keys
from cloudsim.auth.policy import SYSTEM
from cloudsim.cli import ID, app_context, emit, reports_errors
from cloudsim.cli.files import LoadedText, TextFile
from cloudsim.errors import InvalidInput
from cloudsim.models import Role, SshKey, Team, User
from cloudsim.people import service


def team_data(team: Team, members: int | None = None) -> dict[str, object]:
    count = len(team.members) if members is None else members
    return {"id": team.id, "name": team.name, "members": count}


def user_data(user: User) -> dict[str, object]:
    return {
        "id": user.id,
        "email": user.email,
        "name": user.name,
        "role": user.role.value,
        "team": user.team.name if user.team else None,
        "active": user.active,
    }


@click.group()
def team() -> None:
    """Create and list teams."""


@team.command("create")
@click.argument("name")
@click.option("--json", "as_json", is_flag=True, help="Print the team as JSON.")
@reports_errors
def create_team(name: str, as_json: bool) -> None:
    """Create a team called NAME."""
    with app_context():
        created = service.create_team(SYSTEM, name)
        emit(team_data(created), as_json, f"created team {created.name} (id {created.id})")


@team.command("list")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@reports_errors
def list_teams(as_json: bool) -> None:
    """List teams."""
    with app_context():
        teams = service.visible_teams(SYSTEM)
        members = service.member_counts(teams)
        lines = "\n".join(f"{t.id}\t{t.name}\t{members[t.id]} members" for t in teams)
        emit([team_data(t, members[t.id]) for t in teams], as_json, lines or "no teams")


@click.group()
def user() -> None:
    """Create, list and change users."""


@user.command("create")
@click.option("--email", required=True, help="Login e-mail address.")
@click.option(
    "--role",
    type=click.Choice([r.value for r in Role]),
    default=Role.USER.value,
    show_default=True,
)
@click.option("--team", "team_name", help="Team name or id (required for role 'user').")
@click.option("--name", default="", help="Display name.")
@click.option("--password-stdin", is_flag=True, help="Read the password from standard input.")
@click.option("--json", "as_json", is_flag=True, help="Print the user as JSON.")
@reports_errors
def create_user(
    email: str, role: str, team_name: str | None, name: str, password_stdin: bool, as_json: bool
) -> None:
    """Create a user; without --password-stdin a password is generated and printed once."""
    password = sys.stdin.readline().rstrip("\n") if password_stdin else None
    with app_context():
        team_id = service.find_team(team_name).id if team_name else None
        created = service.create_user(
            SYSTEM, email=email, role=role, team_id=team_id, name=name, password=password
        )
        data = user_data(created.user)
        text = f"created {created.user.role.value} {created.user.email} (id {created.user.id})"
        if created.generated_password:
            data["password"] = created.generated_password
            text += f"\npassword: {created.generated_password}"
        emit(data, as_json, text)


@user.command("list")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@reports_errors
def list_users(as_json: bool) -> None:
    """List users."""
    with app_context():
        users = service.visible_users(SYSTEM)
        lines = "\n".join(
            f"{u.id}\t{u.email}\t{u.role.value}\t{u.team.name if u.team else '-'}" for u in users
        )
        emit([user_data(u) for u in users], as_json, lines or "no users")


@user.command("update")
@click.argument("who")
@click.option("--role", type=click.Choice([r.value for r in Role]), help="New role.")
@click.option("--team", "team_name", help="Move to this team (name or id).")
@click.option("--no-team", is_flag=True, help="Take out of any team (officers and admins).")
@click.option("--active/--inactive", default=None, help="Enable or disable the account.")
@click.option("--name", default=None, help="New display name.")
@click.option("--password-stdin", is_flag=True, help="Read a new password from standard input.")
@click.option("--json", "as_json", is_flag=True, help="Print the user as JSON.")
@reports_errors
def update_user(
    who: str,
    role: str | None,
    team_name: str | None,
    no_team: bool,
    active: bool | None,
    name: str | None,
    password_stdin: bool,
    as_json: bool,
) -> None:
    """Change the role, team, active flag, name or password of WHO (e-mail or id).

    The rules are the web's: the last active admin stays an admin; moving a user out of a team
    or disabling them revokes their access to the team's constellations (VPN) at once.
    """
    if team_name and no_team:
        raise click.UsageError("give --team or --no-team, not both")
    password = sys.stdin.readline().rstrip("\n") if password_stdin else None
    with app_context():
        target = service.find_user(who)
        team_id: int | service.Keep | None = service.Keep.KEEP
        if team_name:
            team_id = service.find_team(team_name).id
        elif no_team:
            team_id = None
        updated = service.update_user(
            SYSTEM,
            target.id,
            name=name,
            role=role,
            team_id=team_id,
            active=active,
            password=password or None,
        )
        team = updated.team.name if updated.team else "no team"
        state = "active" if updated.active else "disabled"
        emit(
            user_data(updated),
            as_json,
            f"updated {updated.email}: {updated.role.value}, {team}, {state}",
        )


@user.group("ssh-key")
def ssh_key() -> None:
    """A user's SSH public keys (they log into `team` on the team's field computers)."""


def _key_data(key: SshKey) -> dict[str, object]:
    return {
        "id": key.id,
        "name": key.name,
        "key_type": key.key_type,
        "bits": key.bits,
        "fingerprint": key.fingerprint,
    }


@ssh_key.command("add")
@click.argument("email")
@click.argument("key_file", type=TextFile(), required=False)
@click.option("--generate", is_flag=True, help="Make an ed25519 key; print its private key once.")
@click.option("--name", default="", help="A name for the key.")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@reports_errors
def add_ssh_key(
    email: str, key_file: LoadedText | None, generate: bool, name: str, as_json: bool
) -> None:
    """Add a public key (KEY_FILE, '-' for standard input) for EMAIL, or --generate one."""
    with app_context():
        owner = service.find_user(email)
        if generate == (key_file is not None):
            raise InvalidInput("give a KEY_FILE or --generate (one of them)")
        if key_file is None:
            made = ssh_keys.generate_key(owner, name)
            data = {**_key_data(made.key), "private_key": made.private_key}
            emit(data, as_json, f"{made.key.fingerprint}\n{made.private_key}".rstrip())
            return
        key = ssh_keys.add_key(owner, key_file.read(), name)
        emit(_key_data(key), as_json, f"added {key.key_type} key {key.fingerprint} (id {key.id})")


@ssh_key.command("list")
@click.argument("email")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@reports_errors
def list_ssh_keys(email: str, as_json: bool) -> None:
    """List EMAIL's SSH keys with their fingerprints."""
    with app_context():
        keys = ssh_keys.list_keys(service.find_user(email))
        lines = "\n".join(f"{k.id}\t{k.key_type}\t{k.fingerprint}\t{k.name}" for k in keys)
        emit([_key_data(k) for k in keys], as_json, lines or "no SSH keys")


@ssh_key.command("remove")
@click.argument("email")
@click.argument("key_id", type=ID)
@reports_errors
def remove_ssh_key(email: str, key_id: int) -> None:
    """Remove EMAIL's key KEY_ID; it stops working on the field computers at once."""
    with app_context():
        ssh_keys.delete_key(service.find_user(email), key_id)
        click.echo(f"removed SSH key {key_id}")
