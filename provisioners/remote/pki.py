"""A constellation's VPN PKI: CA, server and client certificates, CRL (PEM in, PEM out).

Pure functions over `cryptography`: nothing touches disk; the caller stores the PEM
(encrypted) and passes it on. Keys are EC P-256, signatures ECDSA-SHA256, as OpenVPN 2.6
wants with `dh none` and TLS 1.3. Certificates carry the key usages `remote-cert-tls`
checks (serverAuth for the router, clientAuth for team users).
"""

from __future__ import annotations

import datetime
import ipaddress
from collections.abc import Iterable
from dataclasses import dataclass, field

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

DEFAULT_CA_DAYS = 3650
DEFAULT_CERT_DAYS = 3650
# OpenVPN rejects every client once the CRL's nextUpdate has passed: keep it far away and
# reissue the CRL (re-apply the router plan) on every revocation anyway.
DEFAULT_CRL_DAYS = 3650
_BACKDATE = datetime.timedelta(minutes=5)  # tolerate clocks a little behind ours


class PKIError(Exception):
    """A PEM input could not be used (wrong kind, not from this CA, malformed)."""


@dataclass(frozen=True)
class CertificateAuthority:
    """The CA of one constellation's VPN."""

    cert_pem: str
    key_pem: str = field(repr=False)


@dataclass(frozen=True)
class IssuedCertificate:
    """A certificate, its private key and what callers look it up by."""

    cert_pem: str
    key_pem: str = field(repr=False)
    serial: int
    common_name: str
    not_after: datetime.datetime


def new_ca(common_name: str, *, days: int = DEFAULT_CA_DAYS) -> CertificateAuthority:
    """Create a self-signed CA that can sign certificates and CRLs."""
    key = ec.generate_private_key(ec.SECP256R1())
    name = _name(common_name)
    now = _now()
    cert = (
        x509.CertificateBuilder()
        .subject_name(name)
        .issuer_name(name)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - _BACKDATE)
        .not_valid_after(now + datetime.timedelta(days=days))
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(_key_usage(cert_sign=True), critical=True)
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
        .sign(key, hashes.SHA256())
    )
    return CertificateAuthority(_cert_pem(cert), _key_pem(key))


def issue_server(
    ca: CertificateAuthority, common_name: str, *, days: int = DEFAULT_CERT_DAYS
) -> IssuedCertificate:
    """Issue the VPN server's certificate (serverAuth)."""
    return _issue(ca, common_name, ExtendedKeyUsageOID.SERVER_AUTH, days)


def issue_tls_server(
    ca: CertificateAuthority,
    common_name: str,
    addresses: Iterable[str],
    *,
    days: int = DEFAULT_CERT_DAYS,
) -> IssuedCertificate:
    """Issue an HTTPS server's certificate (serverAuth) for these IP addresses or DNS names."""
    names: list[x509.GeneralName] = []
    for address in addresses:
        try:
            names.append(x509.IPAddress(ipaddress.ip_address(address)))
        except ValueError:
            names.append(x509.DNSName(address))
    if not names:
        raise PKIError("an HTTPS certificate needs at least one address")
    return _issue(ca, common_name, ExtendedKeyUsageOID.SERVER_AUTH, days, names)


def certificate_fingerprint(cert_pem: str) -> str:
    """Return the SHA-256 of a certificate's DER form, in hex (what a client pins)."""
    return _load_cert(cert_pem).fingerprint(hashes.SHA256()).hex()


def issue_client(
    ca: CertificateAuthority, common_name: str, *, days: int = DEFAULT_CERT_DAYS
) -> IssuedCertificate:
    """Issue a team user's certificate (clientAuth); common_name is e.g. their e-mail."""
    return _issue(ca, common_name, ExtendedKeyUsageOID.CLIENT_AUTH, days)


def issue_crl(
    ca: CertificateAuthority, revoked_serials: Iterable[int], *, days: int = DEFAULT_CRL_DAYS
) -> str:
    """Return a CRL signed by the CA listing these serials (none: an empty, valid CRL)."""
    ca_cert, ca_key = _load_ca(ca)
    now = _now()
    builder = (
        x509.CertificateRevocationListBuilder()
        .issuer_name(ca_cert.subject)
        .last_update(now - _BACKDATE)
        .next_update(now + datetime.timedelta(days=days))
        .add_extension(
            x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()), critical=False
        )
    )
    for serial in sorted(set(revoked_serials)):
        builder = builder.add_revoked_certificate(
            x509.RevokedCertificateBuilder()
            .serial_number(serial)
            .revocation_date(now - _BACKDATE)
            .build()
        )
    crl = builder.sign(ca_key, hashes.SHA256())
    return crl.public_bytes(serialization.Encoding.PEM).decode()


def certificate_serial(cert_pem: str) -> int:
    """Return a certificate's serial number (what a CRL lists)."""
    return _load_cert(cert_pem).serial_number


def certificate_common_name(cert_pem: str) -> str:
    """Return a certificate's subject common name."""
    attributes = _load_cert(cert_pem).subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    if not attributes:
        raise PKIError("the certificate has no common name")
    return str(attributes[0].value)


def revoked_serials(crl_pem: str, ca: CertificateAuthority) -> set[int]:
    """Return the serials a CRL revokes, after checking the CA signed it."""
    try:
        crl = x509.load_pem_x509_crl(crl_pem.encode())
    except ValueError as exc:
        raise PKIError(f"not a PEM CRL: {exc}") from exc
    ca_cert, _ = _load_ca(ca)
    public_key = ca_cert.public_key()
    if not isinstance(public_key, ec.EllipticCurvePublicKey) or not crl.is_signature_valid(
        public_key
    ):
        raise PKIError("the CRL is not signed by this CA")
    return {entry.serial_number for entry in crl}


def _issue(
    ca: CertificateAuthority,
    common_name: str,
    usage: x509.ObjectIdentifier,
    days: int,
    alt_names: list[x509.GeneralName] | None = None,
) -> IssuedCertificate:
    ca_cert, ca_key = _load_ca(ca)
    key = ec.generate_private_key(ec.SECP256R1())
    now = _now()
    not_after = now + datetime.timedelta(days=days)
    serial = x509.random_serial_number()
    cert = (
        x509.CertificateBuilder()
        .subject_name(_name(common_name))
        .issuer_name(ca_cert.subject)
        .public_key(key.public_key())
        .serial_number(serial)
        .not_valid_before(now - _BACKDATE)
        .not_valid_after(not_after)
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(
            _key_usage(key_agreement=usage == ExtendedKeyUsageOID.SERVER_AUTH), critical=True
        )
        .add_extension(x509.ExtendedKeyUsage([usage]), critical=False)
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
        .add_extension(
            x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()), critical=False
        )
    )
    if alt_names:
        cert = cert.add_extension(x509.SubjectAlternativeName(alt_names), critical=False)
    signed = cert.sign(ca_key, hashes.SHA256())
    return IssuedCertificate(_cert_pem(signed), _key_pem(key), serial, common_name, not_after)


def _name(common_name: str) -> x509.Name:
    if not common_name or len(common_name) > 64:
        raise PKIError("a common name must be 1-64 characters")
    return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, common_name)])


def _key_usage(*, cert_sign: bool = False, key_agreement: bool = False) -> x509.KeyUsage:
    return x509.KeyUsage(
        digital_signature=True,
        content_commitment=False,
        key_encipherment=False,
        data_encipherment=False,
        key_agreement=key_agreement,
        key_cert_sign=cert_sign,
        crl_sign=cert_sign,
        encipher_only=False,
        decipher_only=False,
    )


def _load_ca(ca: CertificateAuthority) -> tuple[x509.Certificate, ec.EllipticCurvePrivateKey]:
    cert = _load_cert(ca.cert_pem)
    try:
        key = serialization.load_pem_private_key(ca.key_pem.encode(), password=None)
    except (ValueError, TypeError) as exc:
        raise PKIError("the CA key is not an unencrypted PEM private key") from exc
    if not isinstance(key, ec.EllipticCurvePrivateKey):
        raise PKIError("the CA key is not an EC key")
    if key.public_key().public_numbers() != cert.public_key().public_numbers():  # type: ignore[union-attr]
        raise PKIError("the CA key does not belong to the CA certificate")
    return cert, key


def _load_cert(cert_pem: str) -> x509.Certificate:
    try:
        return x509.load_pem_x509_certificate(cert_pem.encode())
    except ValueError as exc:
        raise PKIError(f"not a PEM certificate: {exc}") from exc


def _cert_pem(cert: x509.Certificate) -> str:
    return cert.public_bytes(serialization.Encoding.PEM).decode()


def _key_pem(key: ec.EllipticCurvePrivateKey) -> str:
    return key.private_bytes(
        serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()
    ).decode()


def _now() -> datetime.datetime:
    return datetime.datetime.now(datetime.UTC).replace(microsecond=0)
