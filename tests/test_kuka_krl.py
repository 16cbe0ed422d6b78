"""The KRL files declare exactly the variables and codes that workers/robot/kuka/variables.py names."""

import re
from pathlib import Path

import pytest

from robocell.workers.robot.kuka import variables as v

KRL = Path(__file__).resolve().parent.parent / "krl"
DECL = re.compile(r"^\s*DECL\s+(?:GLOBAL\s+)?(\w+)\s+(\w+)\s*=\s*(.+?)\s*$", re.IGNORECASE)


def declarations(path: Path) -> dict[str, tuple[str, str]]:
    """name -> (type, initial value) of every DECL line, comments (';') stripped."""
    found = {}
    for line in path.read_text(encoding="utf-8").splitlines():
        code = line.split(";", 1)[0]
        match = DECL.match(code)
        if match:
            name = match.group(2).upper()
            assert name not in found, f"{name} declared twice in {path.name}"
            found[name] = (match.group(1).upper(), match.group(3))
    return found


def code_lines(path: Path) -> list[str]:
    return [line.split(";", 1)[0] for line in path.read_text(encoding="utf-8").splitlines()]


def test_config_additions_declare_exactly_the_globals():
    declared = declarations(KRL / "config_dat_additions.txt")
    assert {name: decl[0] for name, decl in declared.items()} == {var.name: var.type for var in v.GLOBALS}


def test_config_additions_are_declarations_only():
    for line in code_lines(KRL / "config_dat_additions.txt"):
        assert not line.strip() or DECL.match(line), f"not a declaration: {line!r}"


def test_the_program_does_not_redeclare_the_globals():
    local = declarations(KRL / "robocell.dat")
    assert not set(local) & {var.name for var in v.ALL}


@pytest.mark.parametrize("prefix, codes", [("CMD_", v.Command), ("ST_", v.Status), ("ERR_", v.ErrorCode)])
def test_the_program_codes_match(prefix, codes):
    local = declarations(KRL / "robocell.dat")
    in_krl = {name[len(prefix):]: int(value) for name, (kind, value) in local.items()
              if name.startswith(prefix) and kind == "INT"}
    assert in_krl == {code.name: int(code) for code in codes}


def test_the_program_uses_every_global_and_system_variable():
    source = "\n".join(code_lines(KRL / "robocell.src")).upper()
    for var in v.GLOBALS + (v.POS_ACT, v.AXIS_ACT):
        assert re.search(rf"(?<![\w$]){re.escape(var.name)}(?!\w)", source), f"{var.name} unused in robocell.src"


def test_the_program_writes_what_it_owns_and_reads_what_the_bridge_writes():
    source = "\n".join(code_lines(KRL / "robocell.src")).upper()
    for var in v.GLOBALS:
        assigned = re.search(rf"^\s*{var.name}\s*=", source, re.MULTILINE)
        if var.writer == "robot":
            assert assigned, f"robocell.src never sets {var.name}"
        elif var is not v.RC_CMD:  # the program clears RC_CMD, and only RC_CMD, of the bridge's variables
            assert not assigned, f"robocell.src writes {var.name}, which belongs to the bridge"


def test_every_name_in_the_program_is_declared():
    local = declarations(KRL / "robocell.dat")
    globals_ = {var.name for var in v.GLOBALS}
    lines = [line for line in code_lines(KRL / "robocell.src") if not line.startswith("&")]
    # Names only: not system variables ($), enumeration values (#) or structure components (.X).
    words = {match.group(2) for match in re.finditer(r"([.$#]?)\b([A-Z_][A-Z0-9_]*)\b", "\n".join(lines).upper())
             if not match.group(1)}
    krl_words = {"DEF", "END", "DEFFCT", "ENDFCT", "INT", "REAL", "DECL", "IF", "THEN", "ELSE", "ENDIF", "FOR",
                 "TO", "ENDFOR", "LOOP", "ENDLOOP", "WAIT", "SEC", "PTP", "LIN", "RETURN", "AND", "OR", "NOT",
                 "BAS", "COS", "INVERSE", "WHILE", "ENDWHILE", "BOOL", "IN"}
    # The routines, CHECK_COMMAND's local variable and GRIP's parameter.
    routines = {"ROBOCELL", "CHECK_COMMAND", "DOWN", "GRIP", "CLOSING"}
    unknown = words - set(local) - globals_ - krl_words - routines
    assert not unknown, f"names neither declared nor KRL: {sorted(unknown)}"


def test_the_gripper_is_switched_and_confirmed_on_the_io_that_robocell_dat_sets():
    """The output, the input and the time-out are the program's own: numbers in robocell.dat, nowhere else."""
    local = declarations(KRL / "robocell.dat")
    assert local["GRIP_OUT"][0] == local["GRIP_IN"][0] == "INT" and int(local["GRIP_OUT"][1]) >= 1
    assert local["GRIP_TIMEOUT"][0] == "REAL" and float(local["GRIP_TIMEOUT"][1]) > 0
    source = "\n".join(code_lines(KRL / "robocell.src")).upper()
    assert re.search(r"^\s*\$OUT\[GRIP_OUT\]\s*=\s*CLOSING\s*$", source, re.MULTILINE)
    assert re.search(r"^\s*WHILE\s*\(\$IN\[GRIP_IN\] <> CLOSING\) AND \(GRIP_WAITED < GRIP_TIMEOUT\)", source,
                     re.MULTILINE)
    assert not re.search(r"\$(IN|OUT)\[\d", source), "an I/O number written into robocell.src: set it in robocell.dat"
    # Both gripper commands reach GRIP; the open it does not confirm is the gripper's error code.
    assert "GRIP(CUR_CMD == CMD_GRIP_CLOSE)" in source and "CMD_GRIP_OPEN" in source
    assert re.search(r"RETURN ERR_GRIP_TIMEOUT", source)
