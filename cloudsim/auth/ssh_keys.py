"""Users' SSH public keys: validated, fingerprinted, installed in their own account on their
team's field computers.

A user manages only their own keys. Every change starts the refresh of the team's
constellations (`constellation.refresh_access`), which writes each active member's
authorized_keys on the field computers to exactly that member's keys.
"""

from __future__ import annotations

import base64
import binascii
import hashlib
from dataclasses import dataclass

from cryptography.hazmat.primitives.asymmetric import ec, ed25519, rsa
from cryptography.hazmat.primitives.serialization import load_ssh_public_key

from cloudsim.audit.service import record
from cloudsim.errors import InvalidInput, NotFound
from cloudsim.extensions import db
from cloudsim.models import SshKey, User

MAX_KEYS = 10
MIN_RSA_BITS = 3072
NAME_MAX = 80
KEY_TEXT_MAX = 16_384
ACCEPTED_TYPES = (
    "ssh-ed25519",
    "ecdsa-sha2-nistp256",
    "ecdsa-sha2-nistp384",
    "ecdsa-sha2-nistp521",
    "ssh-rsa",
)


@dataclass(frozen=True)
class ParsedKey:
    """A public key that passed every check."""

    key_type: str
    bits: int
    public_key: str  # "TYPE BASE64"
    fingerprint: str  # "SHA256:...", as ssh-keygen -l prints it
    comment: str


@dataclass
class GeneratedKey:
    """A key made for the user: the stored public half and the private half, shown once."""

    key: SshKey
    private_key: str


def parse_public_key(text: str) -> ParsedKey:
    """Validate one OpenSSH public key line; raise InvalidInput saying what is wrong."""
    if len(text) > KEY_TEXT_MAX:
        raise InvalidInput("that is too long for an SSH public key")
    if "PRIVATE KEY" in text:
        raise InvalidInput("that is a private key: paste the public key (the .pub file) only")
    lines = [line for line in text.strip().splitlines() if line.strip()]
    if len(lines) != 1:
        raise InvalidInput("paste exactly one public key (one line, like ssh-ed25519 AAAA... you)")
    words = lines[0].split()
    if len(words) < 2:
        raise InvalidInput("an SSH public key is TYPE BASE64 [COMMENT], e.g. ssh-ed25519 AAAA...")
    key_type, blob, comment = words[0], words[1], " ".join(words[2:])
    if key_type == "ssh-dss":
        raise InvalidInput("DSA keys are too weak: use ed25519 (ssh-keygen -t ed25519)")
    if key_type not in ACCEPTED_TYPES:
        raise InvalidInput(
            f"unsupported key type {key_type[:40]!r}: use one of {', '.join(ACCEPTED_TYPES)} "
            "(and no options before the key)"
        )
    try:
        raw = base64.b64decode(blob, validate=True)
        key = load_ssh_public_key(f"{key_type} {blob}".encode())
    except (binascii.Error, ValueError, TypeError):
        raise InvalidInput("the key's data is malformed (is it cut or wrapped?)") from None
    if isinstance(key, rsa.RSAPublicKey):
        bits = key.key_size
        if bits < MIN_RSA_BITS:
            raise InvalidInput(
                f"this RSA key has {bits} bits; at least {MIN_RSA_BITS} are needed "
                "(or use ed25519: ssh-keygen -t ed25519)"
            )
    elif isinstance(key, ec.EllipticCurvePublicKey):
        bits = key.curve.key_size
    elif isinstance(key, ed25519.Ed25519PublicKey):
        bits = 256
    else:  # pragma: no cover - the type list above admits nothing else
        raise InvalidInput(f"unsupported key type {key_type!r}")
    digest = base64.b64encode(hashlib.sha256(raw).digest()).decode().rstrip("=")
    return ParsedKey(key_type, bits, f"{key_type} {blob}", f"SHA256:{digest}", comment[:NAME_MAX])


def list_keys(user: User) -> list[SshKey]:
    """Return the user's own keys, oldest first."""
    return list(user.ssh_keys)


def add_key(user: User, public_key: str, name: str = "") -> SshKey:
    """Add one of the user's keys and push the team's keys to its field computers."""
    parsed = parse_public_key(public_key)
    return _store(user, parsed, name or parsed.comment or parsed.key_type, "ssh_key.add")


def generate_key(user: User, name: str = "") -> GeneratedKey:
    """Make an ed25519 key pair for the user; only the public half is kept."""
    from cloudsim.launched_constellations.keys import generate_keypair

    pair = generate_keypair(f"{user.email} (made by CloudSim)")
    parsed = parse_public_key(pair.public)
    key = _store(user, parsed, name or "made by CloudSim", "ssh_key.generate")
    return GeneratedKey(key, pair.private)


def delete_key(user: User, key_id: int) -> None:
    """Remove one of the user's own keys; it stops working on the field computers at once."""
    key = db.session.get(SshKey, key_id)
    if key is None or key.user_id != user.id:
        raise NotFound.of("SSH key", key_id)
    db.session.delete(key)
    record(
        "ssh_key.delete",
        user,
        target_type="ssh_key",
        target_id=key_id,
        team_id=user.team_id,
        fingerprint=key.fingerprint,
    )
    db.session.flush()
    _push(user)


def _store(user: User, parsed: ParsedKey, name: str, action: str) -> SshKey:
    name = " ".join(name.split())[:NAME_MAX]
    if any(k.fingerprint == parsed.fingerprint for k in user.ssh_keys):
        raise InvalidInput(f"you already added this key ({parsed.fingerprint})")
    if len(user.ssh_keys) >= MAX_KEYS:
        raise InvalidInput(f"at most {MAX_KEYS} SSH keys; remove one first")
    key = SshKey(
        user=user,
        name=name,
        key_type=parsed.key_type,
        bits=parsed.bits,
        public_key=parsed.public_key,
        fingerprint=parsed.fingerprint,
    )
    db.session.add(key)
    db.session.flush()
    record(
        action,
        user,
        target_type="ssh_key",
        target_id=key.id,
        team_id=user.team_id,
        fingerprint=parsed.fingerprint,
    )
    db.session.flush()
    _push(user)
    return key


def _push(user: User) -> None:
    from cloudsim.launched_constellations.access import refresh_team_access

    if user.team_id is not None:
        refresh_team_access([user.team_id])
