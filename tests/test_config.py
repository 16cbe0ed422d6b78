"""The cell's TOML configuration: defaults that work, and errors that name the file and the field."""

from __future__ import annotations

import re

import pytest

from cell.config import CellConfig, load_config
from cell.errors import ConfigError


def test_no_file_gives_the_defaults_and_a_file_overrides_them(tmp_path):
    assert load_config(None) == CellConfig()
    path = tmp_path / "cell.toml"
    path.write_text('cell_id = "bay2"\n[robot]\nspeed = 0.1\n[scan]\nplan = { standoff = 0.4, '
                    'elevations_deg = [50, 40], azimuths_deg = [0, 180] }\n')
    config = load_config(path)
    assert (config.cell_id, config.robot.speed, config.scan.plan.standoff) == ("bay2", 0.1, 0.4)
    assert config.camera == CellConfig().camera


@pytest.mark.parametrize("text, named", [
    ("cell_id = 'bay 2'\n", "cell_id: String should match pattern"),
    ("[robot]\nsped = 0.1\n", "robot.sped: Extra inputs are not permitted"),
    # TOML has nan and inf: neither is a speed, an angle or a time-out.
    ("[robot]\nspeed = nan\n", "robot.speed: Input should be a finite number"),
    ("[timeouts]\nmove_s = inf\n", "timeouts.move_s: Input should be a finite number"),
    ("[scan]\nplan = { azimuths_deg = [0, nan, 240] }\n", "scan.plan.azimuths_deg.1: Input should be a finite"),
    ("[robot\n", "not valid TOML"),
])
def test_an_invalid_file_is_refused_naming_the_file_and_the_field(tmp_path, text, named):
    path = tmp_path / "cell.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=rf"^{re.escape(str(path))}: .*{named}"):
        load_config(path)


def test_a_missing_file_is_named():
    with pytest.raises(ConfigError, match="configuration file 'nowhere.toml' not found"):
        load_config("nowhere.toml")
