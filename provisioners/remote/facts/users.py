"""Facts about local user accounts and their authorized SSH keys."""

from __future__ import annotations

import re
import shlex
from dataclasses import dataclass

from provisioners.remote.facts.base import Fact

USER_NAME = re.compile(r"^[a-z_][a-z0-9_-]*\$?$")


def check_user_name(name: str) -> str:
    """Return the name, refusing anything useradd would not accept."""
    if not USER_NAME.match(name) or len(name) > 32:
        raise ValueError(f"not a user name: {name!r}")
    return name


@dataclass(frozen=True)
class UserState:
    """A user account as getent and id report it."""

    name: str
    uid: int
    gid: int
    home: str
    shell: str
    group: str
    groups: tuple[str, ...]  # supplementary groups, primary included as id -Gn prints it


@dataclass(frozen=True)
class UserFact(Fact[UserState | None]):
    """Read a user's account, or None when there is no such user."""

    name: str

    def __post_init__(self) -> None:
        check_user_name(self.name)

    @property
    def command(self) -> str:
        """Return getent passwd, primary group and group list of the user."""
        name = shlex.quote(self.name)
        return f'if e=$(getent passwd {name}); then echo "$e"; id -gn {name}; id -Gn {name}; fi'

    def parse(self, stdout: str, exit_code: int) -> UserState | None:
        """Parse the passwd line and group names."""
        lines = stdout.splitlines()
        if not lines:
            return None
        name, _password, uid, gid, _gecos, home, shell = lines[0].split(":")
        return UserState(
            name=name,
            uid=int(uid),
            gid=int(gid),
            home=home,
            shell=shell,
            group=lines[1],
            groups=tuple(lines[2].split()),
        )


@dataclass(frozen=True)
class AuthorizedKeysState:
    """A user's authorized_keys file: where it is, who owns it, what it says."""

    path: str
    group: str
    directory_exists: bool
    content: str | None  # None when the file does not exist


@dataclass(frozen=True)
class AuthorizedKeysFact(Fact[AuthorizedKeysState]):
    """Read a user's authorized_keys (in ~/.ssh unless a path is given)."""

    user: str
    path: str | None = None

    def __post_init__(self) -> None:
        check_user_name(self.user)

    @property
    def command(self) -> str:
        """Return a probe printing path, group, directory and file content."""
        user = shlex.quote(self.user)
        path = (
            shlex.quote(self.path)
            if self.path is not None
            else f'"$(getent passwd {user} | cut -d: -f6)/.ssh/authorized_keys"'
        )
        return (
            f"id -u {user} >/dev/null || exit 3; f={path}; "
            "printf 'path=%s\\n' \"$f\"; "
            f"printf 'group=%s\\n' \"$(id -gn {user})\"; "
            '[ -d "$(dirname "$f")" ] && echo dir=yes || echo dir=no; '
            'if [ -f "$f" ]; then echo file=yes; cat -- "$f"; else echo file=no; fi'
        )

    def parse(self, stdout: str, exit_code: int) -> AuthorizedKeysState:
        """Parse the four header lines, then take the rest as the file's content."""
        header = stdout.split("\n", 4)
        fields = dict(line.split("=", 1) for line in header[:4])
        return AuthorizedKeysState(
            path=fields["path"],
            group=fields["group"],
            directory_exists=fields["dir"] == "yes",
            content=(header[4] if len(header) > 4 else "") if fields["file"] == "yes" else None,
        )
