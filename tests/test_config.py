"""The cell's TOML configuration: defaults that work, and errors that name the file and the field."""

from __future__ import annotations

import re

import pytest

from robocell.wire.access import ROLES
from robocell.wire.config import CellConfig, Roles, load_config
from robocell.wire.errors import ConfigError


EVERY_SECTION = """\
cell_id = "bay2"
run_dir = "/var/lib/robocell"
max_queued = 7
T_flange_cam = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0.12], [0, 0, 0, 1]]

[zenoh]
router = "tcp/192.0.2.1:7448"

[robot]
backend = "kuka"
kuka = { protocol = "opc", host = "192.0.2.20", override = 10 }

[camera]
url = "https://192.0.2.90"
resolution = [1280, 960]

[scan]
table_height = 0.02
plan = { standoff = 0.4, elevations_deg = [50, 40], azimuths_deg = [0, 180] }

[reconstruct]
processes = 4

[sim]
shape = "cylinder"

[timeouts]
move_s = 12.5

[gripper]
max_opening = 0.11

[retention]
recordings_max_mb = 500
"""


def test_a_file_sets_every_section(tmp_path):
    path = tmp_path / "cell.toml"
    path.write_text(EVERY_SECTION)
    config, default = load_config(path), CellConfig()
    assert [name for name in CellConfig.model_fields if getattr(config, name) == getattr(default, name)] == []
    assert (config.cell_id, str(config.run_dir), config.max_queued, config.T_flange_cam[2][3]) == \
        ("bay2", "/var/lib/robocell", 7, 0.12)
    assert config.zenoh.router == "tcp/192.0.2.1:7448"
    assert (config.robot.backend, config.robot.kuka.protocol, config.robot.kuka.host, config.robot.kuka.override,
            config.robot.kuka.port) == ("kuka", "opc", "192.0.2.20", 10, 7766)   # the opc gateway's port
    assert (config.camera.url, config.camera.resolution, config.camera.K) == \
        ("https://192.0.2.90", (1280, 960), default.camera.K)                   # what is left out stays
    assert (config.scan.table_height, config.scan.plan.standoff, config.scan.plan.azimuths_deg) == (0.02, 0.4, [0, 180])
    assert (config.reconstruct.processes, config.sim.shape, config.timeouts.move_s) == (4, "cylinder", 12.5)
    assert config.timeouts.capture_s == default.timeouts.capture_s
    assert (config.gripper.max_opening, config.gripper.friction) == (0.11, default.gripper.friction)


@pytest.mark.parametrize("text, named", [
    ("cell_id = 'bay 2'\n", "cell_id: String should match pattern"),
    ("[robot]\nsped = 0.1\n", "robot.sped: Extra inputs are not permitted"),
    # TOML has nan and inf: neither is a speed, an angle or a time-out.
    ("[robot]\nspeed = nan\n", "robot.speed: Input should be a finite number"),
    ("[timeouts]\nmove_s = inf\n", "timeouts.move_s: Input should be a finite number"),
    ("[scan]\nplan = { azimuths_deg = [0, nan, 240] }\n", "scan.plan.azimuths_deg.1: Input should be a finite"),
    ("[robot\n", "not valid TOML"),
    ("[camera]\nurl = '192.168.0.90'\n", "camera.url: Value error, must be http:// or https:// with a host"),
    ("[camera]\nK = [[600, 0, 320], [0, 600, 240]]\n", "camera.K: List should have at least 3 items"),
    ("[camera]\nresolution = [640, 0]\n", "camera.resolution.1: Input should be greater than 0"),
    ("[camera]\ndist = [0.1]\n", "camera.dist: .*4, 5, 8, 12 or 14 distortion coefficients, got 1"),
    ("[zenoh.roles]\nclients = ['alice']\n", "zenoh.roles.0.clients: Extra inputs are not permitted"),
    ("[zenoh.roles]\nclient = ['alice:secret']\n", "zenoh.roles.0.client.0: String should match pattern"),
    ("[[zenoh.roles]]\ncells = ['_pool']\ndaemon = ['d']\n", "zenoh.roles.0.cells.0: String should match"),
])
def test_an_invalid_file_is_refused_naming_the_file_and_the_field(tmp_path, text, named):
    path = tmp_path / "cell.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=rf"^{re.escape(str(path))}: .*{named}"):
        load_config(path)


def test_a_missing_file_is_named():
    with pytest.raises(ConfigError, match="configuration file 'nowhere.toml' not found"):
        load_config("nowhere.toml")


@pytest.mark.parametrize("url", ["http://root:s3cret@192.168.0.90", "http://root:s3c/ret@192.168.0.90"])
def test_a_camera_password_is_refused_in_the_url_and_never_shown(tmp_path, url):
    path = tmp_path / "cell.toml"
    path.write_text(f"[camera]\nurl = '{url}'\n")
    with pytest.raises(ConfigError, match="camera.url") as info:
        load_config(path)
    assert "s3c" not in str(info.value)


def test_a_camera_password_is_never_written_out(tmp_path):
    """``robocell config`` and the run directory's copy of the configuration leave it out."""
    path = tmp_path / "cell.toml"
    path.write_text("[camera]\nusername = 'root'\npassword = 's3cret'\n")
    config = load_config(path)
    assert config.camera.credentials() == ("root", "s3cret")
    written = config.model_dump_json()
    assert "s3cret" not in written and '"password":null' in written
    copy = tmp_path / "copy.json"
    copy.write_text(written)
    assert load_config(copy).camera.password is None  # not a masked string taken for the password


def test_a_run_directory_that_is_a_file_is_refused(tmp_path):
    (tmp_path / "runs").write_text("")
    path = tmp_path / "cell.toml"
    path.write_text(f"run_dir = '{tmp_path / 'runs'}'\n")
    with pytest.raises(ConfigError, match="run_dir: Value error, .* is a file, not a directory"):
        load_config(path)


def test_a_zenoh_user_needs_its_password_in_the_environment(monkeypatch):
    config = CellConfig.model_validate({"zenoh": {"user": "cell"}})
    monkeypatch.delenv("ROBOCELL_ZENOH_PASSWORD", raising=False)
    with pytest.raises(ConfigError, match="zenoh.user is 'cell', but ROBOCELL_ZENOH_PASSWORD, its password, "
                                          "is not set"):
        config.zenoh.client_settings()
    monkeypatch.setenv("ROBOCELL_ZENOH_PASSWORD", "pw")
    assert config.zenoh.client_settings()["transport/auth/usrpwd/password"] == "pw"


def _subjects(roles: str, tmp_path) -> dict[str, list[str]]:
    """The access control's subjects of a cell "bay1" file with ``roles``."""
    path = tmp_path / "cell.toml"
    path.write_text('cell_id = "bay1"\n[zenoh]\nrouter_settings = { "transport/auth/usrpwd/dictionary_file" = '
                    '"users.txt" }\n' + roles)
    config = load_config(path)
    block = config.zenoh.router_session_settings(config.cell_id)["access_control"]
    return {subject["id"]: subject["usernames"] for subject in block["subjects"]}


def test_roles_are_in_the_files_cell_unless_a_table_names_its_cells(tmp_path):
    assert _subjects('[zenoh.roles]\nclient = ["alice"]\nreconstruct = ["r"]\n', tmp_path) == {
        "client@bay1": ["alice"], "reconstruct:r": ["r"]}
    assert _subjects('[[zenoh.roles]]\nclient = ["alice"]\ndaemon = ["bay1"]\n'
                     '[[zenoh.roles]]\ncells = ["bay2", "bay3"]\nclient = ["alice", "bob"]\nreconstruct = ["r"]\n',
                     tmp_path) == {"client@bay1": ["alice"], "daemon@bay1": ["bay1"], "client@bay2": ["alice", "bob"],
                                   "client@bay3": ["alice", "bob"], "reconstruct:r": ["r"]}


def test_without_roles_the_router_has_no_access_control():
    assert "access_control" not in CellConfig().zenoh.router_session_settings("cell1")
    config = CellConfig.model_validate({"zenoh": {"roles": {"cells": ["bay2"]}}})
    assert "access_control" not in config.zenoh.router_session_settings("cell1")


def test_roles_without_a_users_dictionary_are_refused():
    config = CellConfig.model_validate({"zenoh": {"roles": {"client": ["alice"]}}})
    with pytest.raises(ConfigError, match="zenoh.roles names users, but zenoh.router_settings has no "
                                          "'transport/auth/usrpwd/dictionary_file'"):
        config.zenoh.router_session_settings("cell1")


def test_the_roles_table_has_a_field_for_every_role():
    assert set(Roles.model_fields) - {"cells"} == set(ROLES)


@pytest.mark.parametrize("gripper, message", [
    ({"max_opening": 0}, "gripper: Value error, gripper max_opening must be positive, got 0.0"),
    ({"pad_length": 0.1}, "gripper: Value error, gripper pad_length (0.1) is longer than finger_length (0.045)"),
    ({"friction": -0.5}, "gripper: Value error, gripper friction must be positive, got -0.5"),
    ({"finger_length": "long"}, "gripper.finger_length: Input should be a valid number"),
])
def test_a_gripper_that_cannot_be_is_one_line_naming_the_field(tmp_path, gripper, message):
    path = tmp_path / "cell.toml"
    path.write_text("[gripper]\n" + "".join(f"{k} = {v!r}\n".replace("'", '"') for k, v in gripper.items()))
    with pytest.raises(ConfigError) as error:
        load_config(path)
    assert message in str(error.value) and "\n" not in str(error.value)
