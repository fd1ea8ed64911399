"""EC2 key pairs named by the SHA-256 fingerprint of the public key they hold."""

import base64
import binascii
import hashlib

from provisioners.providers.ec2.api import EC2Api
from provisioners.providers.ec2.errors import InvalidRequestError

KEY_PAIR_PREFIX = "cloudsim-"
_KEY_TYPES = ("ssh-", "ecdsa-", "sk-")


def check_public_key(public_key: object) -> str:
    """Return public_key stripped if it is one OpenSSH public key line, else raise."""
    if not isinstance(public_key, str):
        raise InvalidRequestError("auth must hold one OpenSSH public key line")
    line = public_key.strip()
    fields = line.split()
    if "\n" in line or len(fields) < 2 or not fields[0].startswith(_KEY_TYPES):
        raise InvalidRequestError("auth must hold one OpenSSH public key line")
    try:
        base64.b64decode(fields[1], validate=True)
    except binascii.Error:
        raise InvalidRequestError("auth's public key is not valid base64") from None
    return line


def key_pair_name(public_key: str) -> str:
    """Return the key pair name for public_key: prefix + hex SHA-256 of the key blob."""
    blob = base64.b64decode(check_public_key(public_key).split()[1])
    return KEY_PAIR_PREFIX + hashlib.sha256(blob).hexdigest()


def ensure_key_pair(api: EC2Api, public_key: str) -> str:
    """Import public_key unless a key pair of its name exists; return the key pair's name."""
    name = key_pair_name(public_key)
    if api.describe("DescribeKeyPairs", "keySet", {"key-name": name}):
        return name
    material = base64.b64encode(check_public_key(public_key).encode()).decode()
    # Same name means same key, so one imported concurrently is just as good.
    api.call_ignoring(
        ["InvalidKeyPair.Duplicate"],
        "ImportKeyPair",
        {"KeyName": name, "PublicKeyMaterial": material},
    )
    return name
