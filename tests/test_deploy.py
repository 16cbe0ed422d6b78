"""The deployment examples in deploy/ are configurations the cell really accepts."""

from pathlib import Path

import pytest

from wire.config import load_config

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
