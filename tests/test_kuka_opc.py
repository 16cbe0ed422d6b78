"""The OpenOPC-gateway client against the simulated gateway: a real Pyro5 daemon on loopback.

Neither side uses openopc2 (it caps Python below 3.13): the client is a Pyro5
proxy, and the simulator sends what openopc2's gateway sends.
"""

import asyncio
import socket
import subprocess
import sys
import textwrap
import threading

import Pyro5.client
import Pyro5.serializers
import pytest
import serpent

from robocell.workers.sim.kuka_opc import OPCError
from robocell.workers.sim.kuka import SimKuka
from robocell.wire.backends import SIM_OPC_SERVER
from robocell.workers.robot.kuka.errors import KukaConnectionError, KukaTimeout, KukaVariableError
from robocell.workers.robot.kuka.opc import GatewayError, OpcClient


def run(coroutine, limit: float = 20.0):
    async def bounded():
        async with asyncio.timeout(limit):
            return await coroutine
    return asyncio.run(bounded())


def client_for(sim: SimKuka, **options) -> OpcClient:
    options = {"opc_server": SIM_OPC_SERVER, "connect_timeout": 2.0, "request_timeout": 1.0, **options}
    return OpcClient("127.0.0.1", sim.port, **options)


def test_the_simulators_error_is_on_the_wire_what_openopc2s_gateway_sends():
    """openopc2 0.1.19's OPCError.class_to_dict: the instance's attributes and a fixed class name, no args."""
    error = OPCError("Connect: Invalid class string (KUKA.Wrong)")
    error._pyroTraceback = ["Traceback ...\n"]  # what the daemon adds before it sends an error
    wire = serpent.loads(Pyro5.serializers.serializers["serpent"].dumps(error))
    assert wire == {"__class__": "exceptions.OPCError", "custom_message": "Connect: Invalid class string (KUKA.Wrong)",
                    "_pyroTraceback": ["Traceback ...\n"]}


def test_the_gateway_answers_a_bare_pyro5_proxy_as_openopc2s_does():
    """openopc2's OpenOpcGatewayProxy is this proxy: the object id, connect, read, write and OPCError all fit."""
    def session(port: int):
        with Pyro5.client.Proxy(f"PYRO:OpcDaClient@127.0.0.1:{port}") as proxy:
            with pytest.raises(GatewayError, match="read: not connected"):
                proxy.read("RC_CMD", sync=True)
            with pytest.raises(GatewayError, match=r"Invalid class string \(No.Such.Server\)"):
                proxy.connect("No.Such.Server", "localhost")
            proxy.connect(SIM_OPC_SERVER, "localhost")
            assert proxy.write(("RC_OVERRIDE", 12)) == ["Success"]
            assert proxy.read("RC_OVERRIDE", sync=True)[:2] == (12, "Good")
            rows = proxy.read(["$PERI_RDY", "NOPE"], sync=True)
            assert [row[:3] for row in rows] == [("$PERI_RDY", True, "Good"), ("NOPE", None, "Error")]
            assert proxy.write([("RC_CMD_ID", 3), ("$POS_ACT", "{X 0}")]) == [("RC_CMD_ID", "Success"),
                                                                           ("$POS_ACT", "Error")]
            proxy.close()
        with Pyro5.client.Proxy(f"PYRO:OpcDaClient@127.0.0.1:{port}") as proxy:  # a new connection, a new instance
            with pytest.raises(GatewayError, match="not connected"):
                proxy.read("RC_CMD", sync=True)

    async def scenario():
        async with SimKuka("opc") as sim:
            await asyncio.to_thread(session, sim.port)
            assert sim.controller.writes == [("RC_OVERRIDE", "12"), ("RC_CMD_ID", "3")]

    run(scenario())


def test_the_client_and_the_simulator_need_no_openopc2():
    """In a process where openopc2 cannot be imported, as on Python 3.13: reads, writes and the gateway's errors."""
    script = textwrap.dedent(f"""
        import asyncio, sys
        sys.modules["openopc2"] = None  # any import of it now fails, installed or not
        from robocell.workers.sim.kuka import SimKuka
        from robocell.workers.robot.kuka.errors import KukaConnectionError
        from robocell.workers.robot.kuka.opc import OpcClient

        async def main():
            async with SimKuka("opc") as sim:
                async with OpcClient("127.0.0.1", sim.port, opc_server={SIM_OPC_SERVER!r}) as client:
                    await client.write([("RC_OVERRIDE", "7")])
                    print(await client.read(["RC_OVERRIDE", "$PERI_RDY"]))
                try:
                    await OpcClient("127.0.0.1", sim.port, opc_server="KUKA.Wrong").open()
                except KukaConnectionError as exc:
                    print(str(exc).replace(str(sim.port), "PORT"))

        asyncio.run(asyncio.wait_for(main(), 20))
    """)
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == [
        "{'RC_OVERRIDE': '7', '$PERI_RDY': 'TRUE'}",
        "connecting: the gateway could not connect to OPC server 'KUKA.Wrong' through the OpenOPC gateway at "
        "127.0.0.1:PORT: Connect: Invalid class string (KUKA.Wrong)",
    ]


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
            before = await client.read(["RC_OVERRIDE"])
            sim.controller.inject("drop")
            with pytest.raises(KukaConnectionError, match="writing RC_OVERRIDE"):
                await client.write([("RC_OVERRIDE", "5")])
            # A new connection is a new OpcDaClient on the gateway: the client must connect() it again.
            # The dropped write was never carried out (it cannot land after the next one).
            assert await client.read(["RC_OVERRIDE"]) == before
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
