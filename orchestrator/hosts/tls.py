"""The run's certificates: a CA (made for the run, or the user's) and one certificate per process
of the run, each naming who holds it (:mod:`components.bus_security`), for mutual TLS."""

from __future__ import annotations

import datetime as dt
import os
from pathlib import Path

VALID_FOR = dt.timedelta(days=365)


def _key():
    from cryptography.hazmat.primitives.asymmetric import ec

    return ec.generate_private_key(ec.SECP256R1())


def _pem_key(key) -> bytes:
    from cryptography.hazmat.primitives import serialization

    return key.private_bytes(
        serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()
    )


def _pem_certificate(certificate) -> bytes:
    from cryptography.hazmat.primitives import serialization

    return certificate.public_bytes(serialization.Encoding.PEM)


def _name(common_name: str):
    from cryptography import x509
    from cryptography.x509.oid import NameOID

    return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, common_name)])


def make_ca(common_name: str):
    """(key, certificate) of a new CA."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes

    key, now = _key(), dt.datetime.now(dt.UTC)
    certificate = (
        x509.CertificateBuilder()
        .subject_name(_name(common_name))
        .issuer_name(_name(common_name))
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - dt.timedelta(hours=1))
        .not_valid_after(now + VALID_FOR)
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=True,
                key_cert_sign=True,
                crl_sign=True,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .sign(key, hashes.SHA256())
    )
    return key, certificate


def load_ca(certificate_path: Path, key_path: Path):
    """(key, certificate) of the user's CA; ValueError saying what is wrong with them."""
    from cryptography import x509
    from cryptography.hazmat.primitives import serialization
    from cryptography.hazmat.primitives.asymmetric import dsa, ec, rsa

    try:
        certificate = x509.load_pem_x509_certificate(Path(certificate_path).read_bytes())
    except ValueError as e:
        raise ValueError(f"{certificate_path} is not a PEM certificate ({e})") from None
    try:
        key = serialization.load_pem_private_key(Path(key_path).read_bytes(), password=None)
    except (ValueError, TypeError) as e:
        raise ValueError(f"{key_path} is not an unencrypted PEM private key ({e})") from None
    if not isinstance(key, (rsa.RSAPrivateKey, ec.EllipticCurvePrivateKey, dsa.DSAPrivateKey)):
        raise ValueError(f"{key_path} is not an RSA, EC or DSA key (the run's certificates are signed with SHA-256)")
    spki = (serialization.Encoding.DER, serialization.PublicFormat.SubjectPublicKeyInfo)
    if key.public_key().public_bytes(*spki) != certificate.public_key().public_bytes(*spki):
        raise ValueError(f"{key_path} is not the key of the certificate {certificate_path}")
    try:
        is_ca = certificate.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
    except x509.ExtensionNotFound:
        is_ca = False
    if not is_ca:
        raise ValueError(f"{certificate_path} is not a CA certificate (basicConstraints CA:TRUE)")
    return key, certificate


def issue(ca_key, ca_certificate, common_name: str):
    """(key, certificate) for ``common_name``, signed by the CA, for both ends of a link."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes
    from cryptography.x509.oid import ExtendedKeyUsageOID

    key, now = _key(), dt.datetime.now(dt.UTC)
    certificate = (
        x509.CertificateBuilder()
        .subject_name(_name(common_name))
        .issuer_name(ca_certificate.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - dt.timedelta(hours=1))
        .not_valid_after(now + VALID_FOR)
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(
            x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]), critical=False
        )
        .sign(ca_key, hashes.SHA256())
    )
    return key, certificate


def write_private(path: Path, data: bytes) -> Path:
    """Write a file only its owner reads (mode 0600 from its creation)."""
    descriptor = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(descriptor, "wb") as file:
        file.write(data)
    return path


class RunCertificates:
    """The run's CA and a certificate for each holder (``{label: common name}``), in ``directory``
    (mode 0700): ``files(label)`` are bus settings' ``tls`` for that holder, ``pem(label)`` the same
    as text, for a join file."""

    def __init__(self, directory: Path, holders: dict[str, str], ca: tuple[Path, Path] | None = None, run_id: str = ""):
        self.directory = Path(directory)
        self.directory.mkdir(mode=0o700, parents=True, exist_ok=True)
        ca_key, ca_certificate = load_ca(*ca) if ca else make_ca(f"zenorbit run {run_id}")
        self.ca_path = self.directory / "ca.pem"
        self.ca_path.write_bytes(_pem_certificate(ca_certificate))
        self._texts: dict[str, tuple[bytes, bytes]] = {}
        for label, common_name in holders.items():
            key, certificate = issue(ca_key, ca_certificate, common_name)
            self._texts[label] = (_pem_certificate(certificate), _pem_key(key))
            write_private(self.directory / f"{label}.pem", self._texts[label][0])
            write_private(self.directory / f"{label}.key", self._texts[label][1])

    def files(self, label: str) -> dict[str, str]:
        return {
            "ca": str(self.ca_path),
            "certificate": str(self.directory / f"{label}.pem"),
            "key": str(self.directory / f"{label}.key"),
        }

    def pem(self, label: str) -> dict[str, str]:
        certificate, key = self._texts[label]
        return {"ca": self.ca_path.read_text(), "certificate": certificate.decode(), "key": key.decode()}


def write_pem_files(directory: Path, pem: dict[str, str]) -> dict[str, str]:
    """A join file's certificates as files in ``directory`` (0700): bus settings' ``tls``."""
    directory.mkdir(mode=0o700, parents=True, exist_ok=True)
    files = {}
    for part, suffix in (("ca", "ca.pem"), ("certificate", "own.pem"), ("key", "own.key")):
        files[part] = str(write_private(directory / suffix, pem[part].encode()))
    return files
