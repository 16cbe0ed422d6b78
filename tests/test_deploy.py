"""The deployment examples in deploy/ are configurations the cell really accepts."""

from pathlib import Path

import pytest

from robocell.wire import keys
from robocell.wire.config import load_config

DEPLOY = Path(__file__).resolve().parents[1] / "deploy"


@pytest.mark.parametrize("path", sorted(DEPLOY.glob("*.toml")), ids=lambda p: p.name)
def test_example_configuration_loads(path, monkeypatch):
    monkeypatch.setenv("ROBOCELL_ZENOH_PASSWORD", "secret")
    config = load_config(path)
    assert config.zenoh.router.startswith("tls/")
    settings = config.zenoh.client_settings()
    assert settings["transport/auth/usrpwd/password"] == "secret"
    assert "transport/link/tls/root_ca_certificate" in settings


def test_systemd_units_run_the_documented_commands():
    units = {p.name: p.read_text() for p in (DEPLOY / "systemd").glob("*.service")}
    assert set(units) == {"robocell-router.service", "robocell-cell.service", "robocell-worker@.service"}
    assert "robocell --config /etc/robocell/cell.toml router" in units["robocell-router.service"]
    assert "robocell --config /etc/robocell/cell.toml cell" in units["robocell-cell.service"]
    assert "robocell --config /etc/robocell/cell.toml worker %i" in units["robocell-worker@.service"]


def _allowed(block: dict, subject: str, flow: str, message: str) -> set[str]:
    """The key expressions on which ``subject`` may send (ingress) or receive (egress) ``message``."""
    return {key for rule in block["rules"] if rule["id"].split(" ")[0] == subject
            and flow in rule["flows"] and message in rule["messages"] for key in rule["key_exprs"]}


def test_the_cell_host_router_gives_each_role_its_part():
    config = load_config(DEPLOY / "cell-host.toml")
    block = config.zenoh.router_session_settings(config.cell_id)["access_control"]
    assert block["enabled"] and block["default_permission"] == "deny"
    assert {s["id"]: s["usernames"] for s in block["subjects"]} == {
        "client@cell1": ["alice", "bob"], "observer@cell1": ["dashboard"], "daemon@cell1": ["cell1"],
        "robot@cell1": ["cell1"], "camera@cell1": ["cell1"], "reconstruct:recon1": ["recon1"],
        "reconstruct:recon2": ["recon2"]}
    cell = config.cell_id
    client_asks = _allowed(block, "client@cell1", "ingress", "query")
    assert {keys.submit(cell), keys.cancel(cell, "*"), keys.result(cell, "*")} <= client_asks
    assert not client_asks & {keys.robot_move(cell), keys.camera_capture(cell), keys.reconstructor("*")}
    assert keys.cancel(cell, "*") not in _allowed(block, "observer@cell1", "ingress", "query")
    assert keys.submit(cell) not in _allowed(block, "reconstruct:recon1", "ingress", "query")
    for subject in ("client@cell1", "observer@cell1", "reconstruct:recon1"):
        assert not _allowed(block, subject, "ingress", "put") & {keys.events(cell, "*")}
    # The gripper is the robot's to serve and the daemon's to ask (issue 23: a pick failed without it).
    assert keys.robot_grip(cell) in _allowed(block, "robot@cell1", "ingress", "declare_queryable")
    assert keys.robot_grip(cell) in _allowed(block, "daemon@cell1", "ingress", "query")
    # Each reconstruction worker serves, announces and beats under its own id, and no other.
    for worker in ("recon1", "recon2"):
        subject = f"reconstruct:{worker}"
        assert _allowed(block, subject, "ingress", "declare_queryable") == {keys.reconstructor(worker),
                                                                            keys.reconstructor_info(worker)}
        assert _allowed(block, subject, "ingress", "put") == {keys.reconstructor_heartbeat(worker)}
        assert _allowed(block, subject, "ingress", "liveliness_token") == {keys.reconstructor_alive(worker)}
    serving = {s["id"] for s in block["subjects"]
               if _allowed(block, s["id"], "ingress", "declare_queryable") & {keys.reconstructor("recon1"),
                                                                              keys.reconstructor("*")}}
    assert serving == {"reconstruct:recon1"}


def test_a_reconstruct_user_must_be_a_worker_id():
    from robocell.wire.access import access_control

    with pytest.raises(ValueError, match="reconstruct user 'recon 1' is no worker id"):
        access_control({"cell1": {"reconstruct": ["recon 1"]}})


def test_the_readme_gives_every_user_of_the_roles_a_password_line():
    config = load_config(DEPLOY / "cell-host.toml")
    named = {user for roles in config.zenoh.users_by_role(config.cell_id).values() for users in roles.values()
             for user in users}
    readme = (DEPLOY / "README.md").read_text()
    assert {user for user in named if f"\n   {user}:<" in readme} == named
