"""Certificates and users for tests of Zenoh's TLS and user/password authentication on loopback.

What deploy/README.md makes with openssl, made with the ``cryptography`` package:
a CA, a router certificate for 127.0.0.1 signed by it, and the router's
dictionary of ``user:password`` lines.
"""

from __future__ import annotations

import datetime
import ipaddress
from collections.abc import Mapping
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID

__all__ = ["write_pki", "tls_settings", "router_tls_settings"]


def _certificate(subject: str, key, issuer_name, issuer_key, *, ca: bool) -> x509.Certificate:
    now = datetime.datetime.now(datetime.timezone.utc)
    builder = (x509.CertificateBuilder()
               .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, subject)]))
               .issuer_name(issuer_name).public_key(key.public_key())
               .serial_number(x509.random_serial_number())
               .not_valid_before(now - datetime.timedelta(minutes=5))
               .not_valid_after(now + datetime.timedelta(days=1))
               .add_extension(x509.BasicConstraints(ca=ca, path_length=None), critical=True))
    if not ca:
        builder = builder.add_extension(x509.SubjectAlternativeName(
            [x509.DNSName("localhost"), x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]), critical=False)
    return builder.sign(issuer_key, hashes.SHA256())


def write_pki(directory: Path, users: Mapping[str, str]) -> Path:
    """Write ``ca.pem``, ``router.pem``, ``router.key`` and ``users.txt`` (``users``: name to
    password) into ``directory``; return it."""
    ca_key = ec.generate_private_key(ec.SECP256R1())
    ca_name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "robocell test CA")])
    ca = _certificate("robocell test CA", ca_key, ca_name, ca_key, ca=True)
    router_key = ec.generate_private_key(ec.SECP256R1())
    router = _certificate("127.0.0.1", router_key, ca_name, ca_key, ca=False)
    pem = serialization.Encoding.PEM
    (directory / "ca.pem").write_bytes(ca.public_bytes(pem))
    (directory / "router.pem").write_bytes(router.public_bytes(pem))
    (directory / "router.key").write_bytes(router_key.private_bytes(
        pem, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()))
    (directory / "users.txt").write_text("".join(f"{name}:{password}\n" for name, password in users.items()))
    return directory


def tls_settings(pki: Path) -> dict[str, object]:
    """What every session needs to trust the router (``zenoh.settings``)."""
    return {"transport/link/tls/root_ca_certificate": str(pki / "ca.pem")}


def router_tls_settings(pki: Path) -> dict[str, object]:
    """The router's own keys (``zenoh.router_settings``): its certificate and the users' dictionary."""
    return {
        "transport/link/tls/listen_certificate": str(pki / "router.pem"),
        "transport/link/tls/listen_private_key": str(pki / "router.key"),
        "transport/auth/usrpwd/dictionary_file": str(pki / "users.txt"),
    }
