"""The OpenOPC-gateway client against the simulated gateway: a real Pyro5 daemon on loopback."""

import asyncio
import socket
import threading

import pytest
from openopc2.exceptions import OPCError
from openopc2.gateway_proxy import OpenOpcGatewayProxy

from workers.sim.kuka import SimKuka
from wire.backends import SIM_OPC_SERVER
from workers.robot.kuka.errors import KukaConnectionError, KukaTimeout, KukaVariableError
from workers.robot.kuka.opc import OpcClient


def run(coroutine, limit: float = 20.0):
    async def bounded():
        async with asyncio.timeout(limit):
            return await coroutine
    return asyncio.run(bounded())


def client_for(sim: SimKuka, **options) -> OpcClient:
    options = {"opc_server": SIM_OPC_SERVER, "connect_timeout": 2.0, "request_timeout": 1.0, **options}
    return OpcClient("127.0.0.1", sim.port, **options)


def test_the_gateway_answers_openopc2s_own_proxy():
    """openopc2's proxy, as its CLI uses it: the object id, connect, read, write and OPCError all fit."""
    def session(port: int):
        proxy = OpenOpcGatewayProxy("127.0.0.1", port).get_opc_da_client_proxy()
        try:
            with pytest.raises(OPCError):
                proxy.read("RC_CMD", sync=True)  # not connected yet
            with pytest.raises(OPCError):
                proxy.connect("No.Such.Server", "localhost")
            proxy.connect(SIM_OPC_SERVER, "localhost")
            assert proxy.write(("RC_OVERRIDE", 12)) == ["Success"]
            assert proxy.read("RC_OVERRIDE", sync=True)[:2] == (12, "Good")
            rows = proxy.read(["$PERI_RDY", "NOPE"], sync=True)
            assert [row[:3] for row in rows] == [("$PERI_RDY", True, "Good"), ("NOPE", None, "Error")]
            assert proxy.write([("RC_CMD_ID", 3), ("$POS_ACT", "{X 0}")]) == [("RC_CMD_ID", "Success"),
                                                                           ("$POS_ACT", "Error")]
            proxy.close()
        finally:
            proxy._pyroRelease()

    async def scenario():
        async with SimKuka("opc") as sim:
            await asyncio.to_thread(session, sim.port)
            assert sim.controller.writes == [("RC_OVERRIDE", "12"), ("RC_CMD_ID", "3")]

    run(scenario())


def test_read_and_write_as_krl_text():
    async def scenario():
        async with SimKuka("opc") as sim, client_for(sim) as client:
            assert await client.read(["RC_CMD", "$STOPMESS", "$PERI_RDY"]) == {
                "RC_CMD": "0", "$STOPMESS": "FALSE", "$PERI_RDY": "TRUE"}
            await client.write([("RC_TARGET", "{E6POS: X 500, Y 0, Z 400, A 0, B 0, C 180}"), ("RC_OVERRIDE", "9")])
            values = await client.read(["RC_TARGET", "RC_OVERRIDE", "$POS_ACT", "$AXIS_ACT"])
            assert values["RC_TARGET"] == "{E6POS: X 500, Y 0, Z 400, A 0, B 0, C 180}"
            assert values["RC_OVERRIDE"] == "9" and values["$POS_ACT"].startswith("{E6POS: X 400")
            assert sim.controller.writes[-1] == ("RC_OVERRIDE", "9")  # went as an INT, not as text

    run(scenario())


def test_item_prefix():
    async def scenario():
        async with SimKuka("opc", item_prefix="KRC:") as sim:
            async with client_for(sim, item_prefix="KRC:") as client:
                assert await client.read(["RC_STATUS"]) == {"RC_STATUS": "0"}
            async with client_for(sim) as client:
                with pytest.raises(KukaVariableError, match="could not read RC_STATUS: quality Error"):
                    await client.read(["RC_STATUS"])

    run(scenario())


def test_refusals_name_the_item():
    async def scenario():
        async with SimKuka("opc") as sim, client_for(sim) as client:
            with pytest.raises(KukaVariableError, match="could not read NO_SUCH_VAR"):
                await client.read(["RC_CMD", "NO_SUCH_VAR"])
            with pytest.raises(KukaVariableError, match=r"refused to write \$POS_ACT"):
                await client.write([("$POS_ACT", "{X 0}")])
            with pytest.raises(KukaVariableError, match="RC_CMD: invalid literal"):
                await client.write([("RC_CMD", "abc")])
            assert sim.controller.writes == []

    run(scenario())


def test_an_unknown_opc_server_is_a_connection_error():
    async def scenario():
        async with SimKuka("opc") as sim:
            client = client_for(sim, opc_server="KUKA.Wrong")
            with pytest.raises(KukaConnectionError, match="could not connect to OPC server 'KUKA.Wrong'"):
                await client.read(["RC_CMD"])
            await client.close()

    run(scenario())


def test_a_silent_gateway_times_out_and_the_client_recovers():
    async def scenario():
        async with SimKuka("opc") as sim, client_for(sim, request_timeout=0.3) as client:
            sim.controller.inject("hang")
            with pytest.raises(KukaTimeout, match="reading RC_CMD"):
                await client.read(["RC_CMD"])
            sim.controller.reset()
            assert await client.read(["RC_CMD"]) == {"RC_CMD": "0"}

    run(scenario())


def test_a_dropped_connection_is_reported_and_the_next_call_connects_again():
    async def scenario():
        async with SimKuka("opc") as sim, client_for(sim) as client:
            sim.controller.inject("drop")
            with pytest.raises(KukaConnectionError, match="writing RC_OVERRIDE"):
                await client.write([("RC_OVERRIDE", "5")])
            # A new connection is a new OpcDaClient on the gateway: the client must connect() it again.
            await client.write([("RC_OVERRIDE", "6")])
            assert await client.read(["RC_OVERRIDE"]) == {"RC_OVERRIDE": "6"}

    run(scenario())


def test_no_gateway_is_a_connection_error():
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]

        async def scenario():
            client = OpcClient("127.0.0.1", port, opc_server=SIM_OPC_SERVER, connect_timeout=1.0)
            with pytest.raises(KukaConnectionError, match=f"gateway at 127.0.0.1:{port}"):
                await client.open()
            await client.close()

        run(scenario())


def test_every_proxy_call_runs_on_one_thread():
    async def scenario():
        async with SimKuka("opc") as sim:
            client = client_for(sim)
            async with client:
                for _ in range(5):
                    await asyncio.gather(client.read(["RC_CMD"]), client.read(["RC_STATUS"]))
                threads = list(client._executor._threads)
                owner = await asyncio.get_running_loop().run_in_executor(client._executor, threading.get_ident)
                assert len(threads) == 1 and threads[0].ident == owner != threading.get_ident()
            assert client._executor is None and client._proxy is None

    run(scenario())
