"""Team members' own accounts on the field computers, one shared workspace, a login record.

Each active member of the team has a Unix account of their own (their keys only, uid
MEMBER_UID_BASE + their user id) whose primary group is `team`; the team's code lives in
WORKSPACE, a setgid directory of that group, and members' sessions get umask 0002, so a file
one member writes there is one every teammate may edit. An account CloudSim made for someone
who is no longer a member (disabled, moved, deleted) loses its keys, every process of its uid
and then the account itself, on the refresh that follows. PAM records each session's login
and logout, as root, in LOGIN_LOG; each run's logs carry a copy.
"""

from __future__ import annotations

import shlex
from collections.abc import Callable, Iterator

from constellations.plans.base import (
    MEMBER_UID_BASE,
    MEMBER_UID_SPAN,
    Action,
    MemberAccount,
    PlanContext,
    PlanItem,
)
from provisioners.remote.facts import UserFact, UserState
from provisioners.remote.facts.users import check_user_name
from provisioners.remote.operations import (
    Command,
    Operation,
    OperationError,
    Step,
    absent,
    directory,
    file,
    user,
)
from provisioners.remote.ssh import SSHExecutor, SSHTarget

TEAM_GROUP = "team"  # members' primary group; also the no-login owner of the workspace
WORKSPACE = f"/home/{TEAM_GROUP}"  # the shared account's home before member accounts: code stays
MEMBERS_SUDOERS = f"/etc/sudoers.d/cloudsim-{TEAM_GROUP}"
MEMBER_UMASK = "0002"
LOGIN_LOG = "/var/log/cloudsim/logins.tsv"
LOGIN_RECORDER = "/usr/local/sbin/cloudsim-login-record"
PAM_SNIPPET = "cloudsim-members"  # in /etc/pam.d, included by sshd's
PAM_SSHD = "/etc/pam.d/sshd"
KILL_ATTEMPTS = 50  # 0.1 s apart: a process forking as it is killed gets caught the next time


def member_accounts(ctx: PlanContext) -> list[PlanItem]:
    """Make the workspace, an account per member, the login record; remove former members."""
    sudoers = (
        f"# CloudSim: an officer let the team use sudo\n%{TEAM_GROUP} ALL=(ALL) NOPASSWD:ALL\n"
    )
    return [
        # the shared login of old: it owns the workspace now and nobody logs into it
        user(TEAM_GROUP, login_shell="/usr/sbin/nologin"),
        absent(f"{WORKSPACE}/.ssh/authorized_keys"),
        directory(WORKSPACE, mode=0o2770, owner=TEAM_GROUP, group=TEAM_GROUP),
        *login_record(ctx),
        # former members go first: a renamed member's uid is free again for their new name
        Action("remove former members' accounts", remove_former_members(ctx.members)),
        *(item for member in ctx.members for item in member_account(member)),
        file(MEMBERS_SUDOERS, sudoers, mode=0o440) if ctx.team_sudo else absent(MEMBERS_SUDOERS),
    ]


def member_account(member: MemberAccount) -> list[PlanItem]:
    """Return the member's account, its private home and exactly their keys."""
    name, home = check_user_name(member.name), f"/home/{member.name}"
    return [
        Operation(f"member account {name}", (UserFact(name),), _account_plan(member, home)),
        directory(home, mode=0o700, owner=name, group=TEAM_GROUP),
        directory(f"{home}/.ssh", mode=0o700, owner=name, group=TEAM_GROUP),
        file(
            f"{home}/.ssh/authorized_keys",
            "".join(f"{key}\n" for key in member.keys),
            mode=0o600,
            owner=name,
            group=TEAM_GROUP,
        ),
    ]


def _account_plan(member: MemberAccount, home: str) -> Callable[[UserState | None], Iterator[Step]]:
    name = member.name
    # pam_umask reads the umask from the comment; the member's e-mail says whose account it is
    comment = f"{member.email.replace(':', '_').replace(',', '_')},umask={MEMBER_UMASK}"

    def plan(state: UserState | None) -> Iterator[Step]:
        if state is None:
            useradd = [
                "useradd", "--uid", str(member.uid), "--gid", TEAM_GROUP, "--no-user-group",
                "--create-home", "--home-dir", home, "--shell", "/bin/bash",
                "--comment", comment, "--password", "*", name,
            ]  # fmt: skip
            link = shlex.quote(f"{home}/{TEAM_GROUP}")
            yield Command(f"{shlex.join(useradd)} && ln -sfn {WORKSPACE} {link}")
            return
        if state.uid != member.uid:
            raise OperationError(
                f"an account {name} (uid {state.uid}) exists that CloudSim did not make "
                f"for user {member.user_id}: refusing to take it over"
            )
        if state.group != TEAM_GROUP:
            yield Command(f"usermod --gid {TEAM_GROUP} {shlex.quote(name)}")

    return plan


def remove_former_members(
    members: tuple[MemberAccount, ...],
) -> Callable[[SSHExecutor, SSHTarget], bool]:
    """Return the action that ends and deletes every member account not in members."""
    wanted = {(m.name, m.uid) for m in members}

    def run(executor: SSHExecutor, target: SSHTarget) -> bool:
        listing = executor.run(
            target,
            f"getent passwd | awk -F: '$3 >= {MEMBER_UID_BASE} && "
            f"$3 < {MEMBER_UID_BASE + MEMBER_UID_SPAN} {{print $1, $3}}'",
            timeout=60,
        ).stdout
        found = [(name, int(uid)) for name, uid in (line.split() for line in listing.splitlines())]
        stale = [(name, uid) for name, uid in found if (name, uid) not in wanted]
        for name, uid in stale:
            executor.log(target.name, f"ending {name} (uid {uid}): no longer a member")
            executor.run(target, removal_command(name, uid), timeout=120)
        return bool(stale)

    return run


def removal_command(name: str, uid: int) -> str:
    """Return the command that takes an account's keys, kills its uid's processes (its SSH
    sessions among them) and deletes it with its home, touching no other account."""
    check_user_name(name)
    quoted, home = shlex.quote(name), shlex.quote(f"/home/{name}")
    kill = (
        f"for i in $(seq {KILL_ATTEMPTS}); do pkill -KILL -U {uid} || break; sleep 0.1; done; "
        f"! pgrep -U {uid} >/dev/null"
    )
    return (
        f"rm -f {home}/.ssh/authorized_keys && usermod --lock --expiredate 1 {quoted} && "
        f"{kill} && userdel --force --remove {quoted} 2>/dev/null; "
        f"! getent passwd {quoted} >/dev/null && {kill}"
    )


def login_record(ctx: PlanContext) -> list[PlanItem]:
    """Return the PAM hook that records every SSH session on the machine, as root."""
    recorder = ctx.templates.render("fc/login-record.sh.j2", {"login_log": LOGIN_LOG})
    snippet = ctx.templates.render("fc/pam-cloudsim-members.j2", {"recorder": LOGIN_RECORDER})
    return [
        file(LOGIN_RECORDER, recorder, mode=0o755),
        directory(LOGIN_LOG.rsplit("/", 1)[0], mode=0o750),
        file(f"/etc/pam.d/{PAM_SNIPPET}", snippet),
        Action(f"{PAM_SSHD} includes {PAM_SNIPPET}", _include_snippet),
    ]


def _include_snippet(executor: SSHExecutor, target: SSHTarget) -> bool:
    line = shlex.quote(f"@include {PAM_SNIPPET}")
    result = executor.run(
        target,
        f"grep -qxF {line} {PAM_SSHD} && echo present || echo {line} >> {PAM_SSHD}",
        timeout=30,
    )
    return "present" not in result.stdout
