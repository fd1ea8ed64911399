"""Pieces of the executor that need no server: masking, line splitting, key loading."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
from cryptography.hazmat.primitives import serialization

from provisioners.remote.ssh import ConnectError, SecretMasker, fingerprint, load_private_key
from provisioners.remote.ssh.output import LineStream

from .sshd_server import make_key_pair


def test_masker_replaces_every_secret_longest_first() -> None:
    mask = SecretMasker(["abc", "abcdef", ""])
    mask.add("tok3n")
    assert mask("x abcdef y abc tok3n tok3n") == "x *** y *** *** ***"
    assert mask("nothing secret") == "nothing secret"


def test_line_stream_splits_lines_and_utf8_across_chunks() -> None:
    lines: list[str] = []
    stream = LineStream(lines.append)
    data = "première ligne\r\nzweite Zeile\nno newline at end".encode()
    for index in range(len(data)):  # one byte at a time: splits inside UTF-8 sequences
        stream.feed(data[index : index + 1])
    assert lines == ["première ligne", "zweite Zeile"]
    stream.close()
    assert lines[-1] == "no newline at end"
    assert stream.text == data.decode()


@pytest.mark.parametrize(
    "private_format", [serialization.PrivateFormat.PKCS8, serialization.PrivateFormat.OpenSSH]
)
def test_ed25519_keys_load_from_text_in_both_formats(
    private_format: serialization.PrivateFormat,
) -> None:
    pair = make_key_pair(private_format)
    key = load_private_key("sim", pair.private_pem)
    assert f"{key.get_name()} {key.get_base64()}" == pair.public_line


def test_invalid_key_is_refused_without_echoing_it() -> None:
    garbage = "-----BEGIN PRIVATE KEY-----\nbm90IGEga2V5\n-----END PRIVATE KEY-----\n"
    with pytest.raises(ConnectError) as error:
        load_private_key("sim", garbage)
    assert "'sim'" in str(error.value)
    assert "bm90IGEga2V5" not in str(error.value)


def test_fingerprint_matches_ssh_keygen(tmp_path: Path) -> None:
    public_line = make_key_pair(serialization.PrivateFormat.OpenSSH).public_line
    (tmp_path / "key.pub").write_text(public_line + "\n")
    keygen = subprocess.run(
        ["ssh-keygen", "-lf", str(tmp_path / "key.pub")], capture_output=True, text=True, check=True
    )
    assert fingerprint(public_line) == f"ssh-ed25519 {keygen.stdout.split()[1]}"
