"""Members' own accounts on the field computers, from data: names, uids, keys, the workspace,
sudo and the login record, without any SSH (tests/launched_constellations/test_team_access.py
logs in as them on real hosts)."""

from __future__ import annotations

from dataclasses import replace

import pytest

from constellations.definition import load_kind
from constellations.plans import PLANS, PlanContext
from constellations.plans.base import MEMBER_UID_BASE, MemberAccount, member_account_name
from constellations.plans.members import (
    LOGIN_LOG,
    LOGIN_RECORDER,
    WORKSPACE,
    member_accounts,
    removal_command,
)
from provisioners.remote.facts import UserState
from provisioners.remote.facts.files import PathState
from provisioners.remote.facts.users import check_user_name
from provisioners.remote.operations import Command, Operation, OperationError, Upload

ALICE = MemberAccount(7, "alice@example.org", ("ssh-ed25519 AAAAC3Nza1 alice@example.org",))
BOB = MemberAccount(
    8, "Bob.Smith+robots@example.org", ("ssh-ed25519 AAAAC3Nza2 b", "ssh-rsa AAA3 b")
)


def _context(*members: MemberAccount, sudo: bool = False) -> PlanContext:
    kind = load_kind("vrc", set(PLANS))
    return PlanContext(
        constellation="team7",
        team="Team 7",
        kind=kind,
        machine=kind.machine("fc1"),
        subnet="10.211.9.0/24",
        addresses={m.name: m.address("10.211.9.0/24") for m in kind.machines},
        members=members,
        team_sudo=sudo,
    )


def _item(items: list, name: str) -> Operation:  # type: ignore[type-arg]
    found = next(i for i in items if i.name == name)
    assert isinstance(found, Operation)
    return found


@pytest.mark.parametrize(
    ("email", "user_id", "name"),
    [
        ("alice@example.org", 7, "alice-7"),
        ("Bob.Smith+robots@example.org", 8, "bob_smith_robots-8"),
        ("1st.place@example.org", 9, "m1st_place-9"),
        ("...@example.org", 10, "m-10"),
        ("root@example.org", 11, "root-11"),  # never root itself
        ("x" * 64 + "@example.org", 99999, "x" * 20 + "-99999"),
        ("élodie@example.org", 12, "lodie-12"),
    ],
)
def test_account_names_are_safe_stable_and_unlike_system_accounts(
    email: str, user_id: int, name: str
) -> None:
    assert member_account_name(email, user_id) == name
    assert check_user_name(name) == name and len(name) <= 28
    assert MemberAccount(user_id, email).uid == MEMBER_UID_BASE + user_id


def test_user_ids_outside_the_uid_span_get_no_account() -> None:
    for bad in (0, -1, 100000):
        with pytest.raises(ValueError, match="no field-computer account"):
            MemberAccount(bad, "a@example.org")


def test_each_member_gets_an_account_with_exactly_their_keys_in_the_team_group() -> None:
    items = member_accounts(_context(ALICE, BOB))
    names = [item.name for item in items]
    # the shared login is gone: the team account keeps the workspace, with no keys
    assert names[:3] == [
        "user team",
        "absent /home/team/.ssh/authorized_keys",
        f"directory {WORKSPACE}",
    ]
    assert names.index("remove former members' accounts") < names.index("member account alice-7")
    for member in (ALICE, BOB):
        keys = _item(items, f"file /home/{member.name}/.ssh/authorized_keys")
        [upload] = keys.steps(PathState.absent())
        assert isinstance(upload, Upload)
        assert upload.content == "".join(f"{k}\n" for k in member.keys).encode()
        assert (upload.mode, upload.owner, upload.group) == (0o600, member.name, "team")
        home = _item(items, f"directory /home/{member.name}")
        assert (
            "chmod 0700" in home.steps(PathState("directory", 0o755, member.name, "team"))[0].text
        )  # type: ignore[union-attr]
    workspace = _item(items, f"directory {WORKSPACE}")
    assert workspace.steps(PathState.absent())[0] == Command(f"mkdir -p -m 2770 {WORKSPACE}")


def test_a_new_member_is_created_with_their_uid_group_and_umask_and_no_password() -> None:
    account = _item(member_accounts(_context(BOB)), "member account bob_smith_robots-8")
    [create] = account.steps(None)
    assert isinstance(create, Command)
    words = create.text
    assert f"--uid {MEMBER_UID_BASE + 8} --gid team --no-user-group" in words
    assert "--comment Bob.Smith+robots@example.org,umask=0002" in words
    assert "--password '*'" in words and "ln -sfn /home/team /home/bob_smith_robots-8/team" in words
    mine = UserState(
        "bob_smith_robots-8", MEMBER_UID_BASE + 8, 1000, "/home/x", "/bin/bash", "team", ("team",)
    )
    assert account.steps(mine) == []
    moved = replace(mine, group="users")
    assert account.steps(moved) == [Command("usermod --gid team bob_smith_robots-8")]


def test_an_account_of_that_name_that_cloudsim_did_not_make_is_never_taken_over() -> None:
    account = _item(member_accounts(_context(ALICE)), "member account alice-7")
    stranger = UserState("alice-7", 1001, 1001, "/home/alice-7", "/bin/bash", "alice-7", ())
    with pytest.raises(OperationError, match="refusing to take it over"):
        account.steps(stranger)


def test_sudo_goes_to_the_team_group_only_when_an_officer_allowed_it() -> None:
    allowed = _item(
        member_accounts(_context(ALICE, sudo=True)), "file /etc/sudoers.d/cloudsim-team"
    )
    [upload] = allowed.steps(PathState.absent())
    assert b"%team ALL=(ALL) NOPASSWD:ALL" in upload.content  # type: ignore[union-attr]
    names = [i.name for i in member_accounts(_context(ALICE))]
    assert "absent /etc/sudoers.d/cloudsim-team" in names


def test_every_session_is_recorded_by_pam_as_root() -> None:
    items = member_accounts(_context(ALICE))
    recorder = _item(items, f"file {LOGIN_RECORDER}")
    [upload] = recorder.steps(PathState.absent())
    script = upload.content.decode()  # type: ignore[union-attr]
    assert LOGIN_LOG in script and "PAM_USER" in script and upload.mode == 0o755  # type: ignore[union-attr]
    pam = _item(items, "file /etc/pam.d/cloudsim-members")
    [snippet] = pam.steps(PathState.absent())
    text = snippet.content.decode()  # type: ignore[union-attr]
    assert f"pam_exec.so quiet {LOGIN_RECORDER}" in text and "pam_umask.so" in text
    assert "/etc/pam.d/sshd includes cloudsim-members" in [i.name for i in items]


def test_removal_ends_the_uid_s_processes_and_deletes_only_that_account() -> None:
    command = removal_command("bob-8", MEMBER_UID_BASE + 8)
    assert command.index("rm -f /home/bob-8/.ssh/authorized_keys") < command.index("pkill")
    assert f"pkill -KILL -U {MEMBER_UID_BASE + 8}" in command
    assert "userdel --force --remove bob-8" in command
    with pytest.raises(ValueError, match="not a user name"):
        removal_command("bob; rm -rf /", 1)
