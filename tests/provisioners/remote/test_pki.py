"""The VPN PKI library, checked by OpenSSL itself (no hosts)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
from cryptography import x509
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID

from provisioners.remote import pki


@pytest.fixture(scope="module")
def ca() -> pki.CertificateAuthority:
    return pki.new_ca("test VPN CA")


def openssl_verify(tmp_path: Path, ca: pki.CertificateAuthority, cert: str, crl: str) -> str:
    """Return OpenSSL's verdict on a certificate, with the CRL checked."""
    (tmp_path / "ca.pem").write_text(ca.cert_pem)
    (tmp_path / "crl.pem").write_text(crl)
    (tmp_path / "cert.pem").write_text(cert)
    result = subprocess.run(
        ["openssl", "verify", "-crl_check", "-CAfile", "ca.pem", "-CRLfile", "crl.pem", "cert.pem"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        check=False,
    )
    return result.stdout + result.stderr


def test_certificates_verify_until_revoked(tmp_path: Path, ca: pki.CertificateAuthority) -> None:
    user = pki.issue_client(ca, "operator@team.example")
    other = pki.issue_client(ca, "other@team.example")
    empty = pki.issue_crl(ca, [])
    assert "cert.pem: OK" in openssl_verify(tmp_path, ca, user.cert_pem, empty)
    crl = pki.issue_crl(ca, [user.serial])
    assert "certificate revoked" in openssl_verify(tmp_path, ca, user.cert_pem, crl)
    assert "cert.pem: OK" in openssl_verify(tmp_path, ca, other.cert_pem, crl)
    assert pki.revoked_serials(crl, ca) == {user.serial}


def test_certificates_carry_what_openvpn_checks(ca: pki.CertificateAuthority) -> None:
    server = pki.issue_server(ca, "cloudsim-router")
    client = pki.issue_client(ca, "operator@team.example")
    for issued, usage in (
        (server, ExtendedKeyUsageOID.SERVER_AUTH),
        (client, ExtendedKeyUsageOID.CLIENT_AUTH),
    ):
        cert = x509.load_pem_x509_certificate(issued.cert_pem.encode())
        assert list(cert.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value) == [usage]
        assert cert.extensions.get_extension_for_class(x509.KeyUsage).value.digital_signature
        assert isinstance(cert.public_key(), ec.EllipticCurvePublicKey)
        assert pki.certificate_serial(issued.cert_pem) == issued.serial
    assert pki.certificate_common_name(client.cert_pem) == "operator@team.example"
    assert "PRIVATE KEY" in client.key_pem and "PRIVATE" not in repr(client)


def test_foreign_material_is_refused(ca: pki.CertificateAuthority) -> None:
    stranger = pki.new_ca("someone else")
    with pytest.raises(pki.PKIError, match="not signed by this CA"):
        pki.revoked_serials(pki.issue_crl(stranger, [1]), ca)
    with pytest.raises(pki.PKIError, match="does not belong"):
        pki.issue_client(pki.CertificateAuthority(ca.cert_pem, stranger.key_pem), "x")
    with pytest.raises(pki.PKIError, match="not a PEM certificate"):
        pki.certificate_serial("garbage")
    with pytest.raises(pki.PKIError, match="1-64"):
        pki.issue_client(ca, "")
