"""What the provider does on a server over SSH: prepare it for a node, clean up after one."""

from __future__ import annotations

import itertools
import shlex
from collections.abc import Iterable, Mapping, Sequence

from provisioners.providers.servers.errors import InvalidRequestError
from provisioners.providers.servers.inventory import Server
from provisioners.remote.facts.iptables import iptables_prefix
from provisioners.remote.operations.sysctl import DEFAULT_PERSIST_PATH
from provisioners.remote.ssh import SSHExecutor, SSHTarget

# What CloudSim's deploy plans put on a machine (constellations/plans: common, router, roles,
# software); tests check these against the plans' own constants.
CHAIN_PREFIX = "CLOUDSIM-"
IPTABLES_TABLES = ("filter", "nat", "mangle", "raw")
SERVICES = ("cloudsim.service", "csrouter.service", "openvpn-server@cloudsim.service")
CLOUDSIM_PATHS = (
    "/opt/drcsim",
    "/opt/cloudsim",
    "/opt/csrouter",
    "/usr/local/sbin/csrouter",
    "/etc/cloudsim",
    "/var/lib/cloudsim",
    "/etc/openvpn/server/cloudsim",
    "/etc/openvpn/server/cloudsim.conf",
    "/etc/systemd/system/cloudsim.service",
    "/etc/systemd/system/csrouter.service",
    "/etc/systemd/system/openvpn-server@cloudsim.service.d",
    DEFAULT_PERSIST_PATH,
)
SYSCTL_KEYS = ("net.ipv4.ip_forward",)
# The server's own state, saved at the first prepare of a claim and put back on release.
WORK_DIR = "/var/lib/cloudsim-servers"
ORIGINALS_DIR = f"{WORK_DIR}/original"
RESTORED_FILES = ("/etc/hosts", "/etc/motd")
COMMAND_TIMEOUT_SECONDS = 120.0
_JUMP_OPTIONS = ("-j", "--jump", "-g", "--goto")
_KEY_TYPES = ("ssh-", "ecdsa-", "sk-")

# Sets $keys to the login user's authorized_keys; every script starts with it.
_FIND_KEYS = """set -eu
user={user}
home=$(getent passwd "$user" | cut -d: -f6)
if [ -z "$home" ]; then echo "no home directory for user $user" >&2; exit 3; fi
keys="$home/.ssh/authorized_keys"
"""
# Drops every line holding one of the blobs (a key's base64), keeping owner and mode.
_REMOVE_KEYS = """if [ -f "$keys" ]; then
  tmp="$keys.cloudsim-$$"
  cp -p "$keys" "$tmp"
  awk -v blobs={blobs} 'BEGIN {{ n = split(blobs, b, " "); for (i = 1; i <= n; i++) drop[b[i]] }}
    {{ for (i = 1; i <= NF; i++) if ($i in drop) next; print }}' "$keys" > "$tmp"
  mv -f "$tmp" "$keys"
fi
"""
_ADD_KEY = """group=$(id -gn "$user")
if [ ! -d "$home/.ssh" ]; then install -d -m 700 -o "$user" -g "$group" "$home/.ssh"; fi
if [ ! -f "$keys" ]; then install -m 600 -o "$user" -g "$group" /dev/null "$keys"; fi
if ! awk -v blob={blob} '{{ for (i = 1; i <= NF; i++) if ($i == blob) found = 1 }}
    END {{ exit !found }}' "$keys"; then
  if [ -s "$keys" ] && [ -n "$(tail -c 1 "$keys")" ]; then echo >> "$keys"; fi
  printf '%s\\n' {line} >> "$keys"
fi
"""
_SET_HOSTNAME = """printf '%s\\n' {hostname} > /etc/hostname
hostname {hostname}
"""
# Saves the originals once per claim: a second prepare must not save CloudSim's versions.
_SAVE_ORIGINALS = """originals={originals}
if [ ! -d "$originals" ]; then
  rm -rf "$originals.partial"
  mkdir -p "$originals.partial"
  for path in {files}; do
    name=$(basename "$path")
    if [ -e "$path" ]; then cp -p "$path" "$originals.partial/$name"
    else touch "$originals.partial/$name.absent"; fi
  done
  if command -v ip > /dev/null 2>&1; then
    ip -4 route show default > "$originals.partial/default-route"
  fi
  if command -v iptables-save > /dev/null 2>&1; then
    iptables-save > "$originals.partial/iptables"
  fi
  # /proc/sys rather than sysctl(8): procps is not on every minimal system
  for key in {sysctl_keys}; do
    printf '%s=%s\\n' "$key" "$(cat "/proc/sys/$(printf %s "$key" | tr . /)")"
  done > "$originals.partial/sysctl"
  mv "$originals.partial" "$originals"
fi
"""
_STOP_SERVICES = """if [ -d /run/systemd/system ]; then
  for unit in {units}; do
    if systemctl cat -- "$unit" > /dev/null 2>&1; then systemctl disable --now -- "$unit"; fi
  done
fi
"""
_RELOAD_SYSTEMD = """if [ -d /run/systemd/system ]; then systemctl daemon-reload; fi
"""
_RESTORE_ORIGINALS = """originals={originals}
if [ -d "$originals" ]; then
  for path in {files}; do
    name=$(basename "$path")
    if [ -e "$originals/$name" ]; then cp -p "$originals/$name" "$path"
    elif [ -e "$originals/$name.absent" ]; then rm -f "$path"; fi
  done
  routes="$originals/default-route"
  if [ -f "$routes" ] && [ "$(ip -4 route show default)" != "$(cat "$routes")" ]; then
    while ip -4 route show default | grep -q .; do ip -4 route del default; done
    # each line is a route spec: its words are meant to split
    while read -r route; do
      if [ -n "$route" ]; then ip -4 route add $route; fi
    done < "$routes"
  fi
  if [ -f "$originals/iptables" ]; then
    # iptables-save leaves out tables that had no rules: those are emptied instead
    for table in {tables}; do
      if ! grep -qxF -- "*$table" "$originals/iptables"; then
        iptables -w 10 -t "$table" -F
        iptables -w 10 -t "$table" -X
      fi
    done
    iptables-restore -w 10 < "$originals/iptables"
  fi
  while IFS== read -r key value; do
    printf '%s\\n' "$value" > "/proc/sys/$(printf %s "$key" | tr . /)"
  done < "$originals/sysctl"
  rm -rf {work_dir}
fi
"""


def target(server: Server) -> SSHTarget:
    """Return how the controller logs in to a server with the inventory's credentials."""
    return SSHTarget(
        name=server.name,
        host=server.address,
        port=server.port,
        user=server.user,
        private_key=server.private_key,
        proxy_command=list(server.proxy_command) if server.proxy_command else None,
    )


def key_blob(public_key: str) -> str:
    """Return the base64 part of one OpenSSH public key line, refusing anything else."""
    words = public_key.strip().split()
    if "\n" in public_key.strip() or len(words) < 2 or not words[0].startswith(_KEY_TYPES):
        raise InvalidRequestError("auth must hold one OpenSSH public key line")
    return words[1]


def prepare_script(
    server: Server, hostname: str, public_key: str, stale_keys: Sequence[str]
) -> str:
    """Return the script that installs public_key, saves the originals, sets the hostname."""
    script = _FIND_KEYS.format(user=shlex.quote(server.user))
    stale = _removable_blobs(server, stale_keys)
    if stale:
        script += _REMOVE_KEYS.format(blobs=shlex.quote(" ".join(stale)))
    blob = key_blob(public_key)
    if blob != server.login_key_blob:  # the login key is there already and must stay
        script += _ADD_KEY.format(blob=shlex.quote(blob), line=shlex.quote(public_key.strip()))
    script += _SAVE_ORIGINALS.format(
        originals=shlex.quote(ORIGINALS_DIR),
        files=shlex.join(RESTORED_FILES),
        sysctl_keys=shlex.join(SYSCTL_KEYS),
    )
    return script + _SET_HOSTNAME.format(hostname=shlex.quote(hostname))


def cleanup_script(server: Server, public_keys: Sequence[str], rules: Mapping[str, str]) -> str:
    """Return the script that removes CloudSim's services, chains and files, restores the
    server's saved files, default route, firewall and kernel parameters, gives the server back
    its own name and, last, removes CloudSim's keys. rules: `iptables -S` per table.
    """
    script = _FIND_KEYS.format(user=shlex.quote(server.user))
    script += _STOP_SERVICES.format(units=shlex.join(SERVICES))
    for table, listing in rules.items():
        script += "".join(f"{command}\n" for command in iptables_cleanup(table, listing))
    script += f"rm -rf -- {shlex.join(CLOUDSIM_PATHS)}\n" + _RELOAD_SYSTEMD
    script += _RESTORE_ORIGINALS.format(
        originals=shlex.quote(ORIGINALS_DIR),
        files=shlex.join(RESTORED_FILES),
        work_dir=shlex.quote(WORK_DIR),
        tables=shlex.join(IPTABLES_TABLES),
    )
    script += _SET_HOSTNAME.format(hostname=shlex.quote(server.name))
    # The keys go last: a step that fails stops the script (set -e) with CloudSim's key still
    # there, so the retry of a terminate_incomplete logs in again and cleans what is left.
    blobs = _removable_blobs(server, public_keys)
    if blobs:
        script += _REMOVE_KEYS.format(blobs=shlex.quote(" ".join(blobs)))
    return script


def list_rules_script() -> str:
    """Return the script printing `iptables -S` of each table after a "*table" line."""
    lines = ["if command -v iptables > /dev/null 2>&1; then"]
    for table in IPTABLES_TABLES:
        lines += [f"  echo {shlex.quote('*' + table)}", f"  {iptables_prefix(table, False)} -S"]
    return "\n".join([*lines, "fi", ""])


def parse_rule_listing(output: str) -> dict[str, str]:
    """Split list_rules_script's output into each table's `iptables -S` text."""
    tables: dict[str, list[str]] = {}
    current: list[str] | None = None
    for line in output.splitlines():
        if line.startswith("*"):
            current = tables.setdefault(line[1:], [])
        elif current is not None:
            current.append(line)
    return {table: "\n".join(lines) for table, lines in tables.items()}


def iptables_cleanup(table: str, rules: str) -> list[str]:
    """Return the commands deleting CloudSim's chains of one table and every jump to them."""
    prefix = iptables_prefix(table, False)
    jumps: list[str] = []
    chains: list[str] = []
    for line in rules.splitlines():
        words = shlex.split(line)
        if len(words) == 2 and words[0] == "-N" and words[1].startswith(CHAIN_PREFIX):
            chains.append(words[1])
        elif len(words) > 2 and words[0] == "-A" and not words[1].startswith(CHAIN_PREFIX):
            if (_jump_target(words[2:]) or "").startswith(CHAIN_PREFIX):
                jumps.append(f"{prefix} -D {shlex.join(words[1:])}")
    # A chain can only go once nothing jumps to it, and only when empty.
    return [
        *jumps,
        *(f"{prefix} -F {shlex.quote(chain)}" for chain in chains),
        *(f"{prefix} -X {shlex.quote(chain)}" for chain in chains),
    ]


def prepare(
    executor: SSHExecutor,
    server: Server,
    hostname: str,
    public_key: str,
    stale_keys: Sequence[str] = (),
) -> None:
    """Install the node's key for the login user and give the server the node's hostname."""
    run(executor, server, prepare_script(server, hostname, public_key, stale_keys))


def clean_up(
    executor: SSHExecutor,
    server: Server,
    public_keys: Sequence[str],
    via: SSHTarget | None = None,
) -> None:
    """Remove what CloudSim put on the server and give it back its own state and name.

    via: the way in to use instead of the inventory's (a constellation's route through its
    router, when the constellation's firewall closes the server's own address).
    """
    rules = parse_rule_listing(run(executor, server, list_rules_script(), via))
    run(executor, server, cleanup_script(server, public_keys, rules), via)


def run(executor: SSHExecutor, server: Server, script: str, via: SSHTarget | None = None) -> str:
    """Run a script as root (through sudo for another login user); return its stdout."""
    way_in = via if via is not None else target(server)
    result = executor.run(
        way_in, script, sudo=way_in.user != "root", timeout=COMMAND_TIMEOUT_SECONDS
    )
    return result.stdout


def _removable_blobs(server: Server, public_keys: Iterable[str]) -> list[str]:
    blobs = {key_blob(key) for key in public_keys} - {server.login_key_blob}
    return sorted(blobs)


def _jump_target(rule: Sequence[str]) -> str | None:
    for option, value in itertools.pairwise(rule):
        if option in _JUMP_OPTIONS:
            return value
    return None
