"""``robocell config`` and ``robocell schema``, and editing a user's configuration file in place
(``calibrate --write-config``).

The file is edited with tomlkit, which keeps its comments, its order and its
layout; the edited text must load as a valid configuration before it
replaces the file, in one rename, with the file's mode kept.
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any

from .command import Commands

__all__ = ["register", "update_toml", "write_config", "message_schemas", "message_table", "SCHEMA_DIR", "README_TABLE"]

#: Significant digits written: far below any calibration's error.
_DIGITS = 12


#: Where ``robocell schema --write`` puts the wire contract's JSON Schemas: the repository's ``schemas/``.
SCHEMA_DIR = Path(__file__).resolve().parents[2] / "schemas"  # the repository's, beside robocell/


def register(commands: Commands) -> None:
    commands.add("config", _print_config, help="print the configuration in effect (defaults + --config), as JSON")
    schema = commands.add("schema", _schema, help="the wire contract's messages as JSON Schema",
                          description="Print the JSON Schema of every message on the wire (one document: message "
                                      "name to schema), generated from the pydantic models of wire/messages.py; "
                                      "with --write, write them as schemas/<Message>.json (the repository's copy, "
                                      "which a test checks is current).")
    schema.add_argument("--write", nargs="?", const=str(SCHEMA_DIR), metavar="DIR",
                        help=f"write one file per message into DIR (default {SCHEMA_DIR.name}/ of the repository), "
                             f"removing those of messages that are gone")


def message_schemas() -> dict[str, str]:
    """Each message of the wire contract (the ``Message`` models of ``wire.messages``) as its JSON
    Schema's text, by file name (``ScanRequest.json``): what ``schema --write`` writes."""
    import json

    from robocell.wire import messages

    models = [getattr(messages, name) for name in messages.__all__]
    found = {model.__name__: model for model in models
             if isinstance(model, type) and issubclass(model, messages.Message) and model is not messages.Message}
    return {f"{name}.json": json.dumps(model.model_json_schema(), indent=2) + "\n"
            for name, model in sorted(found.items())}


#: The README's table of messages lies between these lines; ``schema --write`` rewrites it.
README_TABLE = ("<!-- messages: made by `robocell schema --write` -->", "<!-- messages end -->")


def message_table() -> str:
    """A Markdown table of the messages: each one's fields, ``?`` after an optional one (it has a
    default), from the same JSON Schemas."""
    import json

    rows = ["| message | fields (`?`: optional) |", "|---|---|"]
    for name, text in message_schemas().items():
        schema = json.loads(text)
        required = set(schema.get("required", []))
        fields = ", ".join(f"`{field}`" + ("" if field in required else "?") for field in schema["properties"])
        rows.append(f"| [`{name.removesuffix('.json')}`](schemas/{name}) | {fields} |")
    return "\n".join(rows)


def _write_readme_table(readme: Path) -> bool:
    begin, end = README_TABLE
    text = readme.read_text(encoding="utf-8")
    if begin not in text or end not in text:
        return False
    head, rest = text.split(begin, 1)
    _, tail = rest.split(end, 1)
    readme.write_text(f"{head}{begin}\n{message_table()}\n{end}{tail}", encoding="utf-8")
    return True


def _schema(args: argparse.Namespace) -> int:
    import json

    schemas = message_schemas()
    if args.write is None:
        print(json.dumps({name.removesuffix(".json"): json.loads(text) for name, text in schemas.items()}, indent=2))
        return 0
    directory = Path(args.write)
    directory.mkdir(parents=True, exist_ok=True)
    for stale in sorted(set(p.name for p in directory.glob("*.json")) - set(schemas)):
        (directory / stale).unlink()
    for name, text in schemas.items():
        (directory / name).write_text(text, encoding="utf-8")
    print(f"wrote {len(schemas)} schemas to {directory}")
    readme = directory.parent / "README.md"
    if readme.is_file() and _write_readme_table(readme):
        print(f"and the table of messages in {readme}")
    return 0


def _print_config(args: argparse.Namespace) -> int:
    from robocell.wire.config import load_config

    print(load_config(args.config).model_dump_json(indent=2))
    return 0


def _toml_value(value: Any):
    """A number or a (nested) list of numbers as TOML floats; a matrix one row per line."""
    import math

    import tomlkit

    if isinstance(value, (list, tuple)) or hasattr(value, "tolist"):
        rows = [_toml_value(v) for v in (value.tolist() if hasattr(value, "tolist") else value)]
        array = tomlkit.array()
        array.extend(rows)
        return array.multiline(any(isinstance(row, list) for row in rows))
    number = float(value)
    if not math.isfinite(number):
        raise ValueError(f"cannot write {number} to a configuration")
    return float(f"{number:.{_DIGITS}g}")


def update_toml(text: str, table: str, values: dict[str, Any]) -> str:
    """``text`` with ``values`` set in ``table`` (dotted for a sub-table, "" for the top level), everything
    else as it was: comments, order, layout.

    Raises
    ------
    ValueError
        If ``text`` is not TOML (tomlkit's ``ParseError``).
    TypeError, tomlkit.exceptions.TOMLKitError
        If ``table`` names something that is not a table.

    Examples
    --------
    >>> print(update_toml("# cell\\nx = 1\\n\\n[camera]\\nK = [[1, 0, 0],\\n  [0, 1, 0], [0, 0, 1]]  # old\\n",
    ...                   "camera", {"K": [[2, 0, 1], [0, 2, 1], [0, 0, 1]], "dist": [0.1, 0, 0, 0, 0]}), end="")
    # cell
    x = 1
    <BLANKLINE>
    [camera]
    K = [
        [2.0, 0.0, 1.0],
        [0.0, 2.0, 1.0],
        [0.0, 0.0, 1.0],
    ]  # old
    dist = [0.1, 0.0, 0.0, 0.0, 0.0]
    """
    import tomlkit

    document = tomlkit.parse(text)
    section = document
    for name in table.split(".") if table else []:
        if name not in section:
            section[name] = tomlkit.table()
        section = section[name]
    for key, value in values.items():
        section[key] = _toml_value(value)
    return tomlkit.dumps(document)


def write_config(path: str | Path, table: str, values: dict[str, Any]) -> None:
    """Set ``values`` in ``table`` of the configuration file ``path`` (created if missing).

    Raises
    ------
    ConfigError
        If the file is not valid TOML, or would not be a valid configuration afterwards
        (the file is then left as it was).
    """
    import tomllib

    from pydantic import ValidationError
    from tomlkit.exceptions import TOMLKitError

    from robocell.wire.config import CellConfig
    from robocell.wire.errors import ConfigError
    from robocell.wire.messages import field_errors

    path = Path(path)
    text = path.read_text(encoding="utf-8") if path.exists() else ""
    try:
        new = update_toml(text, table, values)
        CellConfig.model_validate(tomllib.loads(new))
    # tomlkit's and tomllib's parse errors, pydantic's ValidationError; TypeError: a key where a table is
    except (ValueError, TypeError, TOMLKitError) as exc:
        detail = field_errors(exc) if isinstance(exc, ValidationError) else str(exc)
        where = f"[{table}] " if table else ""
        raise ConfigError(f"cannot update {path} ({detail}); set {where}{', '.join(values)} by hand") from exc
    # A new file beside the old, then one rename: a crash leaves either file whole, never half of one.
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as file:
            file.write(new)
        if path.exists():
            shutil.copymode(path, tmp)  # a file holding a camera password stays private
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
