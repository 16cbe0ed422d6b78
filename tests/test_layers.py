"""The layers of the house (README "Layout"): what each package may import of the others."""

import ast
import tomllib
from pathlib import Path

import pytest
import setuptools

TOP = Path(__file__).resolve().parents[1]
PACKAGES = ("core_cy", "wire", "cell", "workers", "robocell")
#: What each package must not import (the simulator logs its own truth: the daemon imports no fake).
FORBIDDEN = {
    "core_cy": {"wire", "cell", "workers", "robocell"},
    "wire": {"cell", "workers", "robocell"},
    "cell": {"workers", "robocell"},
    "workers": {"cell", "robocell"},
}


def layer(module: str) -> str:
    """The layer a module belongs to: everything is robocell.*, the API and the CLI are "robocell"."""
    names = module.split(".")
    if names[0] != "robocell":
        return names[0]
    return names[1] if len(names) > 1 and names[1] in PACKAGES else "robocell"


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
            if layer(module) in FORBIDDEN[package]:
                wrong.append(f"{where} imports {module}")
    assert wrong == []


def test_the_distribution_installs_one_import_name():
    """Only ``robocell`` at the top: a user's own ``cell`` or ``wire`` must not collide with ours
    (issue 24); the links under robocell/ bring every folder in, subpackages included."""
    include = tomllib.loads((TOP / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]["find"]["include"]
    packages = set(setuptools.find_packages(str(TOP), include=include))
    assert {package.split(".")[0] for package in packages} == {"robocell"}
    assert {"robocell.cli", "robocell.cell", "robocell.wire", "robocell.core_cy", "robocell.workers.sim",
            "robocell.workers.robot.kuka"} <= packages
