"""User accounts and their authorized SSH keys."""

from __future__ import annotations

import shlex
from collections.abc import Iterator, Sequence
from pathlib import PurePosixPath

from provisioners.remote.facts import AuthorizedKeysFact, AuthorizedKeysState, UserFact, UserState
from provisioners.remote.facts.users import check_user_name
from provisioners.remote.operations.base import Command, Operation, Step, Upload


def user(
    name: str,
    *,
    login_shell: str = "/bin/bash",
    home: str | None = None,
    groups: Sequence[str] = (),
    system: bool = False,
) -> Operation:
    """Ensure a user exists with this login shell, home and supplementary groups."""
    for group in groups:
        check_user_name(group)
    quoted = shlex.quote(name)

    def plan(state: UserState | None) -> Iterator[Step]:
        if state is None:
            words = ["useradd", "--create-home", "--shell", login_shell]
            if home is not None:
                words += ["--home-dir", home]
            if groups:
                words += ["--groups", ",".join(groups)]
            if system:
                words.append("--system")
            yield Command(shlex.join([*words, name]))
            return
        if state.shell != login_shell:
            yield Command(f"usermod --shell {shlex.quote(login_shell)} {quoted}")
        if home is not None and state.home != home:
            yield Command(f"usermod --home {shlex.quote(home)} --move-home {quoted}")
        missing = [group for group in groups if group not in state.groups]
        if missing:
            yield Command(f"usermod --append --groups {shlex.quote(','.join(missing))} {quoted}")

    return Operation(f"user {name}", (UserFact(name),), plan)


def authorized_key(user_name: str, public_key: str, *, path: str | None = None) -> Operation:
    """Ensure a user's authorized_keys (or the file at path) contains a public key."""
    key_type, blob, *_comment = public_key.split()
    key_line = public_key.strip()

    def plan(state: AuthorizedKeysState) -> Iterator[Step]:
        existing = state.content or ""
        for line in existing.splitlines():
            # options may precede the key ('from="..." ssh-ed25519 AAAA...'): match type + blob
            words = line.split()
            if any(words[i : i + 2] == [key_type, blob] for i in range(len(words))):
                return
        directory = str(PurePosixPath(state.path).parent)
        if not state.directory_exists:
            quoted_dir = shlex.quote(directory)
            owner = shlex.quote(f"{user_name}:{state.group}")
            yield Command(f"mkdir -p -m 0700 {quoted_dir} && chown {owner} {quoted_dir}")
        if existing and not existing.endswith("\n"):
            existing += "\n"
        yield Upload(
            state.path,
            (existing + key_line + "\n").encode(),
            mode=0o600,
            owner=user_name,
            group=state.group,
        )

    return Operation(
        f"authorized key {key_type} {blob[-12:]} for {user_name}",
        (AuthorizedKeysFact(user_name, path),),
        plan,
    )
