"""The KukaVarProxy client: its bytes, and the client against real TCP servers on loopback."""

import asyncio
import contextlib
import socket
import struct

import pytest

from robocell.workers.sim.kuka import SimKuka
from robocell.workers.robot.kuka import kvp
from robocell.workers.robot.kuka.e6pos import parse_e6axis, parse_e6pos
from robocell.workers.robot.kuka.errors import KukaConnectionError, KukaProtocolError, KukaTimeout, KukaVariableError
from robocell.workers.robot.kuka.kvp import READ, WRITE, KvpClient, decode_request, encode_request, encode_response


def run(coroutine, limit: float = 20.0):
    async def bounded():
        async with asyncio.timeout(limit):
            return await coroutine
    return asyncio.run(bounded())


@contextlib.asynccontextmanager
async def raw_server(answer):
    """A TCP server that reads one request per call and writes ``answer(msg_id, body)`` back."""
    async def serve(reader, writer):
        with contextlib.suppress(asyncio.IncompleteReadError, ConnectionError):
            while True:
                msg_id, length = struct.unpack(">HH", await reader.readexactly(4))
                writer.write(answer(msg_id, await reader.readexactly(length)))
                await writer.drain()
        writer.close()

    server = await asyncio.start_server(serve, "127.0.0.1", 0)
    try:
        yield server.sockets[0].getsockname()[1]
    finally:
        server.close()
        await server.wait_closed()


def test_request_bytes_are_those_of_kukavarproxy():
    # msg id, length of the rest, function, name length, name [, value length, value]
    assert encode_request(0x0102, READ, "$OV_PRO") == b"\x01\x02\x00\x0a\x00\x00\x07$OV_PRO"
    assert encode_request(3, WRITE, "$OV_PRO", "50") == b"\x00\x03\x00\x0e\x01\x00\x07$OV_PRO\x00\x0250"
    assert decode_request(encode_request(3, WRITE, "A", "B")[4:]) == (WRITE, "A", "B")
    # function, value length, value, status length, status
    assert encode_response(5, READ, "100", True) == b"\x00\x05\x00\x09\x00\x00\x03100\x00\x01\x01"


def test_too_long_values_are_refused_before_sending():
    with pytest.raises(ValueError, match="length field"):
        encode_request(1, WRITE, "X", "a" * 70000)


@pytest.mark.parametrize("length_of", [lambda value: 1 + 2 + len(value) + 2 + 1, lambda value: len(value) + 3])
def test_responses_are_read_by_their_fields_under_either_length_convention(length_of):
    def answer(msg_id, body):
        value = b"100"
        return struct.pack(">HH", msg_id, length_of(value)) + b"\x00\x00\x03" + value + b"\x00\x01\x01"

    async def scenario():
        async with raw_server(answer) as port, KvpClient("127.0.0.1", port) as client:
            return [await client.read_var("$OV_PRO") for _ in range(3)]

    assert run(scenario()) == ["100"] * 3


@pytest.mark.parametrize("answer, error", [
    (lambda msg_id, body: encode_response(msg_id + 1, READ, "1", True), "answered message"),
    (lambda msg_id, body: struct.pack(">HH", msg_id, 77) + b"\x00\x00\x011\x00\x01\x01", "does not match"),
    (lambda msg_id, body: encode_response(msg_id, WRITE, "1", True), "function 1"),
])
def test_malformed_responses_are_protocol_errors(answer, error):
    async def scenario():
        async with raw_server(answer) as port, KvpClient("127.0.0.1", port) as client:
            with pytest.raises(KukaProtocolError, match=error):
                await client.read_var("RC_CMD")

    run(scenario())


def test_read_and_write_through_the_simulator():
    async def scenario():
        async with SimKuka("kvp") as sim, KvpClient("127.0.0.1", sim.port) as client:
            await client.ping()
            assert await client.read(["RC_CMD", "RC_STATUS", "$STOPMESS", "$PERI_RDY"]) == {
                "RC_CMD": "0", "RC_STATUS": "0", "$STOPMESS": "FALSE", "$PERI_RDY": "TRUE"}
            await client.write([("RC_OVERRIDE", "15"), ("RC_CMD_ID", "7")])
            assert await client.read_var("RC_OVERRIDE") == "15"
            assert sim.controller.writes == [("RC_OVERRIDE", "15"), ("RC_CMD_ID", "7")]
            position = parse_e6pos(await client.read_var("$POS_ACT"))
            assert (position.x, position.y, position.z, position.s, position.t) == (400, 0, 600, 2, 35)
            assert len(parse_e6axis(await client.read_var("$AXIS_ACT")).axes) == 6

    run(scenario())


def test_variables_the_controller_refuses():
    async def scenario():
        async with SimKuka("kvp") as sim, KvpClient("127.0.0.1", sim.port) as client:
            with pytest.raises(KukaVariableError, match="could not read NO_SUCH_VAR"):
                await client.read_var("NO_SUCH_VAR")
            with pytest.raises(KukaVariableError, match=r"could not write \$POS_ACT"):
                await client.write_var("$POS_ACT", "{X 0}")
            with pytest.raises(KukaVariableError, match="could not write RC_CMD = abc"):
                await client.write_var("RC_CMD", "abc")
            assert await client.read_var("RC_CMD") == "0"  # the connection survives a refusal

    run(scenario())


def test_a_silent_proxy_times_out_and_the_next_request_reconnects():
    async def scenario():
        async with SimKuka("kvp") as sim, KvpClient("127.0.0.1", sim.port, request_timeout=0.2) as client:
            sim.controller.inject("hang")
            with pytest.raises(KukaTimeout, match="reading RC_CMD: no answer .* within 0.2 s"):
                await client.read_var("RC_CMD")
            sim.controller.reset()
            assert await client.read_var("RC_CMD") == "0"

    run(scenario())


def test_a_dropped_connection_is_reported_and_the_next_request_reconnects():
    async def scenario():
        async with SimKuka("kvp") as sim, KvpClient("127.0.0.1", sim.port) as client:
            sim.controller.inject("drop")
            with pytest.raises(KukaConnectionError, match="closed the connection"):
                await client.write_var("RC_OVERRIDE", "10")
            assert await client.read_var("RC_OVERRIDE") == "0"  # dropped before it was done
            await client.write_var("RC_OVERRIDE", "10")
            assert await client.read_var("RC_OVERRIDE") == "10"

    run(scenario())


def test_nobody_listening_is_a_connection_error():
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]  # bound, not listening: connections are refused

        async def scenario():
            client = KvpClient("127.0.0.1", port, connect_timeout=1.0)
            with pytest.raises(KukaConnectionError, match=f"no connection to KukaVarProxy at 127.0.0.1:{port}"):
                await client.read_var("RC_CMD")
            await client.close()

        run(scenario())


def test_an_idle_connection_is_renewed_before_kukavarproxy_drops_it(monkeypatch):
    monkeypatch.setattr(kvp, "_IDLE_RECONNECT_S", 0.0)

    async def scenario():
        async with SimKuka("kvp") as sim, KvpClient("127.0.0.1", sim.port) as client:
            await client.read_var("RC_CMD")
            first = client._writer
            await asyncio.sleep(0.01)
            await client.read_var("RC_CMD")
            assert client._writer is not first

    run(scenario())
