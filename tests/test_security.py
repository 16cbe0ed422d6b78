"""Zenoh with TLS and user/password authentication, on loopback with generated certificates.

A client without the credentials, or without the CA, cannot even connect, so
it can neither submit a job nor read an image.
"""

import asyncio

import pytest

from robocell.demo import free_port
from tests.pki import router_tls_settings, tls_settings, write_pki
from wire.errors import TransportError
from wire.transport import Response, Transport


@pytest.fixture(scope="module")
def pki(tmp_path_factory):
    """A CA, a router certificate for 127.0.0.1, and a user dictionary."""
    return write_pki(tmp_path_factory.mktemp("pki"), {"cell1": "right-password"})


def _run(coroutine):
    return asyncio.run(asyncio.wait_for(coroutine, 60))


async def _with_router(pki, check):
    endpoint = f"tls/127.0.0.1:{free_port()}"
    router = await Transport.open(endpoint, mode="router", settings={**tls_settings(pki), **router_tls_settings(pki)})
    try:
        return await check(endpoint)
    finally:
        await router.close()


def _client_settings(pki, *, ca=True, user="cell1", password="right-password"):
    settings = tls_settings(pki) if ca else {}
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
