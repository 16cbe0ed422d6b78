"""The layers of the house (README "Layout"): what each package may import of the others."""

import ast
from pathlib import Path

import pytest

TOP = Path(__file__).resolve().parents[1]
PACKAGES = ("core_cy", "wire", "cell", "workers", "robocell")
#: What each package must not import. The daemon draws the simulated object's truth beside the fit in
#: a simulated cell's recordings: that one import of the simulator is allowed (``cell/recorder.py``).
FORBIDDEN = {
    "core_cy": {"wire", "cell", "workers", "robocell"},
    "wire": {"cell", "workers", "robocell"},
    "cell": {"workers", "robocell"},
    "workers": {"cell", "robocell"},
}
ALLOWED = {("cell/recorder.py", "workers.sim.scene")}


def imports(path: Path) -> set[str]:
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.add(node.module)
    return found


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_a_package_imports_nothing_from_the_layers_above_it(package):
    wrong = []
    for path in sorted((TOP / package).rglob("*.py")):
        where = path.relative_to(TOP).as_posix()
        for module in sorted(imports(path)):
            if module.split(".")[0] in FORBIDDEN[package] and (where, module) not in ALLOWED:
                wrong.append(f"{where} imports {module}")
    assert wrong == []
