"""KukaBackend over each protocol against the simulated controller: moves, refusals, faults, time-outs."""

import asyncio
import contextlib
import math

import numpy as np
import pytest

from pydantic import TypeAdapter

from robocell.wire.backends import KukaConfig, KukaKvpConfig, KukaOpcConfig, Workspace
from robocell.workers.sim.kuka import SimKuka
from robocell.workers.robot.kuka import variables as v
from robocell.workers.robot.kuka.backend import KukaBackend, check_move, make_client
from robocell.wire.errors import DrivesOff, EmergencyStop, MoveFailed, MoveRefused
from robocell.workers.robot.kuka.errors import (ControllerBusy, ControllerRefused, GripperTimeout, KukaConnectionError,
                                       KukaError, KukaTimeout, Unreachable)

PROTOCOLS = ["kvp", "opc"]
FAST = {"speed_mm_s": 20000.0, "rotation_deg_s": 20000.0}
SLOW = {"speed_mm_s": 100.0, "rotation_deg_s": 100.0}  # 300 mm at 20 %: 15 s


def run(coroutine, limit: float = 30.0):
    async def bounded():
        async with asyncio.timeout(limit):
            return await coroutine
    return asyncio.run(bounded())


def flange(x: float, y: float, z: float, tilt_deg: float = 0.0) -> np.ndarray:
    """A flange pose looking straight down (tilted about the base y axis by ``tilt_deg``)."""
    t = math.radians(tilt_deg)
    tilt = np.array([[math.cos(t), 0, math.sin(t)], [0, 1, 0], [-math.sin(t), 0, math.cos(t)]])
    pose = np.eye(4)
    pose[:3, :3] = tilt @ np.diag([1.0, -1.0, -1.0])
    pose[:3, 3] = [x, y, z]
    return pose


@contextlib.asynccontextmanager
async def kuka_cell(protocol, sim=None, workspace=None, **config):
    async with SimKuka(protocol, **{**FAST, **(sim or {})}) as simulated:
        settings = {"protocol": protocol, "port": simulated.port, "connect_timeout_s": 2.0, "request_timeout_s": 1.0,
                    "ack_timeout_s": 0.5, "move_timeout_s": 10.0, "poll_period_s": 0.01, **config}
        async with KukaBackend.from_config(TypeAdapter(KukaConfig).validate_python(settings), workspace or Workspace()) as backend:
            yield simulated.controller, backend


async def wait_for_status(controller, status, limit=5.0):
    async with asyncio.timeout(limit):
        while controller.read(v.RC_STATUS.name) != status:
            await asyncio.sleep(0.005)


@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_moves_reach_their_targets_and_report_progress(protocol):
    async def scenario():
        async with kuka_cell(protocol) as (controller, backend):
            np.testing.assert_allclose(backend.pose(), controller.pose(), atol=1e-12)
            progress = []
            for target, motion in [(flange(0.6, 0.2, 0.3, 20), "ptp"), (flange(0.5, -0.3, 0.4), "lin")]:
                reached = await backend.move(target, lambda pose, moving: progress.append((pose, moving)),
                                             motion=motion)
                np.testing.assert_allclose(reached, target, atol=1e-6)
                np.testing.assert_allclose(controller.pose(), target, atol=1e-6)
                np.testing.assert_allclose(backend.pose(), reached)
            assert [(command, override) for _, command, _, override in controller.commands] == [(1, 20), (2, 20)]
            assert progress and all(moving for _, moving in progress)
            assert controller.read(v.RC_CMD.name) == 0 and controller.read(v.RC_STATUS.name) == v.Status.DONE

    run(scenario())


@pytest.mark.parametrize("protocol", PROTOCOLS)
@pytest.mark.parametrize("target, options, limit, message", [
    (flange(1.5, 0.0, 0.3), {}, "workspace", "x = 1.5 m is above the workspace maximum"),
    (flange(0.6, 0.0, 0.01), {}, "workspace", "z = 0.01 m is below"),
    (flange(0.6, 0.0, 0.3, 85), {}, "orientation", "tilted 85.0 deg"),
    (flange(0.6, 0.0, 0.3), {"override": 50}, "override", "override 50 % is outside 1..30 %"),
    (flange(0.6, 0.0, 0.3), {"override": 0}, "override", "override 0 %"),
    (flange(0.6, 0.0, 0.3), {"motion": "circ"}, "motion", "unknown motion type 'circ'"),
    (np.diag([1.0, 1.0, 2.0, 1.0]), {}, "pose", "the pose is not a rigid transform"),
    (np.full((4, 4), np.nan), {}, "pose", "non-finite"),
])
def test_a_refused_move_never_reaches_the_controller(protocol, target, options, limit, message):
    async def scenario():
        async with kuka_cell(protocol) as (controller, backend):
            with pytest.raises(MoveRefused, match=message) as refused:
                await backend.move(target, lambda pose, moving: None, **options)
            assert refused.value.limit == limit
            assert controller.writes == [] and controller.commands == []

    run(scenario())


@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_the_program_checks_again_with_its_own_limits(protocol):
    wide = Workspace(min=[-2.0, -2.0, 0.0], max=[2.0, 2.0, 2.0], max_tilt_deg=90)

    async def scenario():
        async with kuka_cell(protocol, workspace=wide) as (controller, backend):
            with pytest.raises(ControllerRefused, match=r"RC_ERROR 3\): the target is outside") as refused:
                await backend.move(flange(1.2, 0.0, 0.3), lambda pose, moving: None)
            assert refused.value.code == v.ErrorCode.OUTSIDE_WORKSPACE
            with pytest.raises(ControllerRefused, match=r"RC_ERROR 4\)"):
                await backend.move(flange(0.6, 0.0, 0.3, 85), lambda pose, moving: None)
            np.testing.assert_allclose(controller.pose(), flange(0.4, 0.0, 0.6))  # never moved

    run(scenario())


@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_an_unreachable_pose(protocol):
    async def scenario():
        async with kuka_cell(protocol) as (controller, backend):
            controller.inject("unreachable")
            with pytest.raises(Unreachable, match="no axis solution") as refused:
                await backend.move(flange(0.6, 0.0, 0.3), lambda pose, moving: None)
            assert refused.value.code == v.ErrorCode.UNREACHABLE
            await backend.move(flange(0.6, 0.0, 0.3), lambda pose, moving: None)  # the next one goes

    run(scenario())


@pytest.mark.parametrize("protocol", PROTOCOLS)
@pytest.mark.parametrize("fault, error", [("emergency_stop", EmergencyStop), ("drives_off", DrivesOff)])
def test_a_stopped_controller_is_not_commanded(protocol, fault, error):
    async def scenario():
        async with kuka_cell(protocol) as (controller, backend):
            controller.inject(fault)
            with pytest.raises(error, match="before the move"):
                await backend.move(flange(0.6, 0.0, 0.3), lambda pose, moving: None)
            assert controller.writes == []

    run(scenario())


@pytest.mark.parametrize("protocol", PROTOCOLS)
@pytest.mark.parametrize("fault, error, message", [
    ("emergency_stop", EmergencyStop, r"\$STOPMESS"), ("drives_off", DrivesOff, r"\$PERI_RDY is FALSE")])
def test_a_stop_during_the_move(protocol, fault, error, message):
    async def scenario():
        async with kuka_cell(protocol, sim=SLOW) as (controller, backend):
            start, target = backend.pose(), flange(0.6, 0.2, 0.3)
            move = asyncio.create_task(backend.move(target, lambda pose, moving: None))
            await wait_for_status(controller, v.Status.MOVING)
            await asyncio.sleep(0.05)
            controller.inject(fault)
            with pytest.raises(error, match=message):
                await move
            stopped = controller.pose()[:3, 3]
            assert 0 < np.linalg.norm(stopped - start[:3, 3]) < np.linalg.norm(target[:3, 3] - start[:3, 3])
            # Acknowledged and started again, the program resumes the interrupted move: busy until it ends.
            controller.acknowledge()
            with pytest.raises(ControllerBusy, match="RC_CMD is 1"):
                await backend.move(target, lambda pose, moving: None)
            controller.reset()
            controller.speed_mm_s = controller.rotation_deg_s = 20000.0
            np.testing.assert_allclose(await backend.move(target, lambda pose, moving: None), target, atol=1e-6)

    run(scenario())


@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_a_program_that_does_not_run_times_out_and_the_command_is_withdrawn(protocol):
    async def scenario():
        async with kuka_cell(protocol) as (controller, backend):
            controller.inject("stall")
            with pytest.raises(KukaTimeout, match="did not take the command within 0.5 s.*withdrawn"):
                await backend.move(flange(0.6, 0.0, 0.3), lambda pose, moving: None)
            assert controller.read(v.RC_CMD.name) == 0 and controller.commands == []
            controller.reset()
            await asyncio.sleep(0.05)
            assert controller.commands == []  # the withdrawn command never runs

    run(scenario())


@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_a_move_that_takes_too_long_times_out(protocol):
    async def scenario():
        async with kuka_cell(protocol, sim=SLOW, move_timeout_s=0.3) as (controller, backend):
            with pytest.raises(KukaTimeout, match="did not end within 0.3 s"):
                await backend.move(flange(0.6, 0.2, 0.3), lambda pose, moving: None)
            controller.reset()

    run(scenario())


@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_a_dropped_connection_during_a_move(protocol):
    async def scenario():
        async with kuka_cell(protocol, sim={"speed_mm_s": 2000.0}) as (controller, backend):
            move = asyncio.create_task(backend.move(flange(0.6, 0.2, 0.3), lambda pose, moving: None))
            await wait_for_status(controller, v.Status.MOVING)
            controller.inject("drop")
            with pytest.raises(KukaConnectionError):
                await move
            await wait_for_status(controller, v.Status.DONE)
            target = flange(0.5, 0.0, 0.4)  # the bridge reconnects for the next move
            np.testing.assert_allclose(await backend.move(target, lambda pose, moving: None), target, atol=1e-6)

    run(scenario())


@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_a_silent_bridge_times_out(protocol):
    async def scenario():
        async with kuka_cell(protocol, request_timeout_s=0.3) as (controller, backend):
            controller.inject("hang")
            with pytest.raises(KukaTimeout):
                await backend.move(flange(0.6, 0.0, 0.3), lambda pose, moving: None)
            controller.reset()

    run(scenario())


@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_command_ids_never_repeat_the_last_finished_one(protocol):
    async def scenario():
        async with kuka_cell(protocol) as (controller, backend):
            for done_id, expected in [(5, 6), (32767, 1)]:
                controller._ints[v.RC_DONE_ID.name] = done_id  # as left by an earlier bridge
                await backend.move(flange(0.6, 0.0, 0.3 + 0.01 * expected), lambda pose, moving: None)
                assert controller.commands[-1][0] == expected == controller.read(v.RC_DONE_ID.name)

    run(scenario())


@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_the_gripper_closes_where_the_arm_stands_and_says_what_its_input_says(protocol):
    low = lambda pose: pose[2, 3] < 0.35  # the simulated gripper holds a part only below 35 cm

    async def scenario():
        async with kuka_cell(protocol, sim={"holds": low, "grip_in": 7, "grip_timeout_s": 0.2}) as (controller,
                                                                                                     backend):
            await backend.move(flange(0.6, 0.0, 0.3), lambda pose, moving: None)
            grip = await backend.grip(True)
            assert (grip.closed, grip.holding, grip.width) == (True, True, None)
            assert grip.reason.startswith("held: $IN[7] confirmed it in 0.05 s")
            assert controller.gripper_output and controller.gripper_input
            grip = await backend.grip(False)
            assert (grip.closed, grip.holding) == (False, None)
            assert not controller.gripper_output and not controller.gripper_input
            await backend.move(flange(0.6, 0.0, 0.4), lambda pose, moving: None)
            grip = await backend.grip(True)  # nothing between the jaws up here: a miss, not an error
            assert (grip.closed, grip.holding) == (True, False)
            assert grip.reason == ("the gripper's input $IN[7] (robocell.dat GRIP_IN) did not confirm a hold within "
                                   "0.2 s (GRIP_TIMEOUT): nothing between the jaws, or the gripper did not close")
            assert controller.gripper_output and not controller.gripper_input
            assert [command for _, command, _, _ in controller.commands] == [1, 3, 4, 1, 3]

    run(scenario())


@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_a_gripper_that_does_not_let_go(protocol):
    async def scenario():
        async with kuka_cell(protocol, sim={"grip_in": 7, "grip_timeout_s": 0.2}) as (controller, backend):
            assert (await backend.grip(True)).holding is True
            controller.inject("grip_stuck")  # the input keeps saying it holds
            words = (r"the gripper did not let go: its input \$IN\[7\] \(robocell.dat GRIP_IN\) still said it held "
                     r"a part after 0.2 s \(GRIP_TIMEOUT\); it may still hold it")
            with pytest.raises(GripperTimeout, match=words) as failed:
                await backend.grip(False)
            assert failed.value.code == v.ErrorCode.GRIP_TIMEOUT
            assert not controller.gripper_output and controller.gripper_input
            controller.reset()
            assert (await backend.grip(False)).closed is False  # the input follows again
            assert not controller.gripper_input

    run(scenario())


@pytest.mark.parametrize("protocol", PROTOCOLS)
@pytest.mark.parametrize("fault, error, message", [
    ("emergency_stop", EmergencyStop, r"into the gripper's closing: a stop message is active on the controller "
                                      r"\(\$STOPMESS\)"),
    ("drives_off", DrivesOff, r"into the gripper's closing: the drives are off")])
def test_a_stop_during_a_grip(protocol, fault, error, message):
    async def scenario():
        async with kuka_cell(protocol, sim={"grip_delay_s": 30.0}) as (controller, backend):
            grip = asyncio.create_task(backend.grip(True))
            await wait_for_status(controller, v.Status.MOVING)
            controller.inject(fault)
            with pytest.raises(error, match=message):
                await grip
            controller.reset()
            controller.grip_delay_s = 0.01
            with pytest.raises(error, match="before the gripper's opening"):
                controller.inject(fault)
                await backend.grip(False)
            controller.reset()
            assert (await backend.grip(True)).holding is True

    run(scenario())


@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_a_grip_that_takes_too_long_times_out(protocol):
    async def scenario():
        async with kuka_cell(protocol, sim={"grip_delay_s": 30.0}, grip_timeout_s=0.3) as (controller, backend):
            with pytest.raises(KukaTimeout, match="the gripper's closing did not end within 0.3 s"):
                await backend.grip(True)
            controller.reset()

    run(scenario())


def test_pose_before_open_and_a_move_that_ends_elsewhere():
    backend = KukaBackend(make_client(KukaKvpConfig()), Workspace())  # never opened
    with pytest.raises(KukaError, match="no pose read from KukaVarProxy at 127.0.0.1:7000 yet"):
        backend.pose()
    target = flange(0.6, 0.0, 0.3)
    backend._check_reached(flange(0.6, 0.0, 0.3009), target)
    with pytest.raises(MoveFailed, match="ended 2.00 mm and 0.00 deg from its target"):
        backend._check_reached(flange(0.6, 0.0, 0.302), target)
    with pytest.raises(MoveFailed, match="1.00 deg"):
        backend._check_reached(flange(0.6, 0.0, 0.3, 1.0), target)


def test_check_move_gives_the_e6pos_to_command():
    position = check_move(flange(0.6, 0.1, 0.3), Workspace(), override=20, max_override=30, motion="lin")
    assert (position.x, position.y, position.z, position.a, position.b, position.c) == pytest.approx(
        (600, 100, 300, 0, 0, 180))


def test_config_refuses_a_default_override_above_the_maximum():
    with pytest.raises(ValueError, match="override 40 % is above max_override 30 %"):
        KukaKvpConfig(override=40)
    assert KukaOpcConfig().port == 7766 and KukaKvpConfig().port == 7000
