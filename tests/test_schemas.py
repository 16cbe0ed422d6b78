"""The wire contract's JSON Schemas (schemas/*.json) and the README's table of messages are those the
pydantic models make today (regenerate both with `robocell schema --write`), and what the README
shows on the wire passes them."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from robocell.cli.config import README_TABLE, SCHEMA_DIR, message_schemas, message_table

REPO = Path(__file__).resolve().parents[1]
REGENERATE = "out of date: run `robocell schema --write` and commit schemas/ and README.md"


def test_the_schema_files_are_current():
    made = message_schemas()
    on_disk = {path.name: path.read_text(encoding="utf-8") for path in SCHEMA_DIR.glob("*.json")}
    assert sorted(on_disk) == sorted(made), REGENERATE
    for name, text in made.items():
        assert on_disk[name] == text, f"schemas/{name} {REGENERATE}"


def test_the_readme_table_of_messages_is_current():
    begin, end = README_TABLE
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    assert readme.split(begin, 1)[1].split(end, 1)[0].strip() == message_table(), f"README.md {REGENERATE}"


def test_every_message_of_the_key_table_has_a_schema():
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    named = set(re.findall(r"`([A-Z][A-Za-z]+)`", readme.split("| key | kind | payload |", 1)[1].split("\n\n", 1)[0]))
    assert named <= {name.removesuffix(".json") for name in message_schemas()}


@pytest.mark.parametrize(("message", "example", "valid"), [
    ("ErrorReply", {"schema_version": 1, "error": "invalid ScanRequest: target: ...", "kind": "RequestError",
                    "details": {}}, True),
    ("ScanRequest", {"schema_version": 1, "target": [0.6, 0.0, 0.05]}, True),
    ("ScanRequest", {"schema_version": 1, "target": [0.6, 0.0, 0.05],
                     "plan": {"standoff": 0.35, "elevations_deg": [55, 40], "azimuths_deg": [0, 180]},
                     "pick": {"approach_m": 0.1, "lift_m": 0.1, "place": [0.6, 0.2]}, "label": "x"}, True),
    ("ScanRequest", {"schema_version": 2, "target": [0.6, 0.0, 0.05]}, True),
    ("ScanRequest", {"schema_version": 3, "target": [0.6, 0.0, 0.05]}, False),
    ("ScanRequest", {"target": [0.6, 0.0, 0.05]}, False),   # a client's request names its version
    ("CancelRequest", {"schema_version": 2, "token": "t" * 43}, True),
    ("CancelRequest", {"token": "t" * 43}, False),
    ("ScanRequest", {"target": [0.6, 0.0]}, False),
    ("ScanRequest", {"target": [0.6, 0.0, 0.05], "colour": "red"}, False),
])
def test_the_schemas_judge_messages_as_the_models_do(message, example, valid):
    jsonschema = pytest.importorskip("jsonschema")
    from robocell.wire import messages

    schema = json.loads((SCHEMA_DIR / f"{message}.json").read_text())
    errors = list(jsonschema.Draft202012Validator(schema).iter_errors(example))
    assert (not errors) is valid, errors
    model = getattr(messages, message)
    try:  # as the daemon reads a client's request
        messages.parse_request(model, json.dumps(example), messages.REQUEST_LIMITS["submit"])
    except ValueError:
        assert not valid
    else:
        assert valid
