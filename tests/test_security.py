"""Zenoh with TLS and user/password authentication, on loopback with generated certificates.

A client without the credentials, or without the CA, cannot even connect, so
it can neither submit a job nor read an image.
"""

import asyncio
import datetime
import ipaddress

import pytest
from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID

from robocell.demo import free_port
from wire.errors import TransportError
from wire.transport import Response, Transport


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


@pytest.fixture(scope="module")
def pki(tmp_path_factory):
    """A CA, a router certificate for 127.0.0.1, and a user dictionary."""
    directory = tmp_path_factory.mktemp("pki")
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
    (directory / "users.txt").write_text("cell1:right-password\n")
    return directory


def _run(coroutine):
    return asyncio.run(asyncio.wait_for(coroutine, 60))


async def _with_router(pki, check):
    endpoint = f"tls/127.0.0.1:{free_port()}"
    router = await Transport.open(endpoint, mode="router", settings={
        "transport/link/tls/listen_certificate": str(pki / "router.pem"),
        "transport/link/tls/listen_private_key": str(pki / "router.key"),
        "transport/link/tls/root_ca_certificate": str(pki / "ca.pem"),
        "transport/auth/usrpwd/dictionary_file": str(pki / "users.txt"),
    })
    try:
        return await check(endpoint)
    finally:
        await router.close()


def _client_settings(pki, *, ca=True, user="cell1", password="right-password"):
    settings = {}
    if ca:
        settings["transport/link/tls/root_ca_certificate"] = str(pki / "ca.pem")
    if user is not None:
        settings["transport/auth/usrpwd/user"] = user
        settings["transport/auth/usrpwd/password"] = password
    return settings


def test_client_with_credentials_and_ca_is_served(pki):
    async def check(endpoint):
        server = await Transport.open(endpoint, settings=_client_settings(pki))
        client = await Transport.open(endpoint, settings=_client_settings(pki))
        try:
            async def image(request):
                return Response(b"\xff\xd8 a JPEG \xff\xd9", encoding="image/jpeg")

            server.serve("robocell/cell1/camera/capture", image)
            for _ in range(50):  # the queryable's declaration reaches the router asynchronously
                try:
                    return await client.query("robocell/cell1/camera/capture", timeout=2)
                except TransportError:
                    await asyncio.sleep(0.1)
            raise AssertionError("the authenticated client was never served")
        finally:
            await client.close()
            await server.close()

    reply = _run(_with_router(pki, check))
    assert reply.payload.startswith(b"\xff\xd8") and reply.encoding == "image/jpeg"


@pytest.mark.parametrize("settings, why", [
    (dict(user=None), "no credentials"),
    (dict(password="wrong-password"), "wrong password"),
    (dict(user="intruder", password="right-password"), "unknown user"),
    (dict(ca=False), "does not trust the router's certificate"),
])
def test_client_without_the_right_credentials_cannot_connect(pki, settings, why):
    async def check(endpoint):
        with pytest.raises(TransportError, match="cannot reach the Zenoh router"):
            client = await Transport.open(endpoint, settings=_client_settings(pki, **settings))
            await client.close()

    _run(_with_router(pki, check))


def test_plain_tcp_to_a_tls_router_is_refused(pki):
    async def check(endpoint):
        with pytest.raises(TransportError):
            client = await Transport.open(endpoint.replace("tls/", "tcp/"), settings=_client_settings(pki))
            await client.close()

    _run(_with_router(pki, check))
