"""Shared fixtures; and the core runs here as the ``robocell`` command runs it, on one BLAS thread."""

import os

# As robocell/cli/main.py does, and before numpy is imported: the fit's small problems gain nothing from
# BLAS threads and lose much to them beside other work (the suite's core tests, and every child process
# the cell tests start through ``robocell``, then run alike).
for _variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")

import contextlib  # noqa: E402
import shutil  # noqa: E402
from collections.abc import Callable, Iterator  # noqa: E402

import pytest  # noqa: E402

from tests.bundles import write_sphere_bundle  # noqa: E402


@pytest.fixture(scope="session")
def sphere_bundle_template(tmp_path_factory):
    """A sphere bundle rendered once; tests get copies they may edit."""
    return write_sphere_bundle(tmp_path_factory.mktemp("template") / "sphere")


@pytest.fixture
def sphere_bundle(sphere_bundle_template, tmp_path):
    return shutil.copytree(sphere_bundle_template, tmp_path / "sphere")


@pytest.fixture(scope="session")
def printed_scene(tmp_path_factory):
    """The simulator's printed scenes (``printed_set(seed)``) rendered once each for the whole run: a call
    ``printed_scene(seed, name)`` gives the scene's spec and its bundle's directory, written with its
    empty workspace (``background{i}.jpg``). Many tests segment or fit the same scene, some from its
    images alone and some with the backgrounds; the images, true masks and poses are the same bytes
    either way (each view and each background has its own noise), so one rendering serves both, and a
    test from the images alone leaves the backgrounds out."""
    from robocell.workers.sim.scans import printed_set

    written: dict[tuple[int, str], tuple[object, object]] = {}

    def scene(seed: int, name: str):
        if (seed, name) not in written:
            spec = {spec.name: spec for spec in printed_set(seed)}[name]
            written[seed, name] = spec, spec.write(tmp_path_factory.mktemp(f"printed-{seed}"), backgrounds=True)
        return written[seed, name]

    return scene


# --- cells that several test modules share ---------------------------------------------------------
# A cell's start is seconds of six processes' imports, and an idle cell still takes the CPU of its
# heartbeats: a shared cell starts for the first module that uses it and stops after the last.

_shared_cells: dict[str, tuple[contextlib.ExitStack, object]] = {}
_modules_to_come: dict[str, set[str]] = {}   # shared cell -> modules that use it and have not ended


@pytest.hookimpl(trylast=True)  # after -k and -m have deselected
def pytest_collection_modifyitems(items):
    for item in items:
        for name in ("printed_box_cell", "red_box_cell"):
            if name in getattr(item, "fixturenames", ()):
                _modules_to_come.setdefault(name, set()).add(item.module.__name__)


def pytest_sessionfinish(session):
    for stack, _ in _shared_cells.values():  # left by a run that stopped early, or by xdist's share
        stack.close()
    _shared_cells.clear()


def _shared_cell(name: str, module: str, start: Callable[[], contextlib.AbstractContextManager]) -> Iterator:
    if name not in _shared_cells:
        stack = contextlib.ExitStack()
        _shared_cells[name] = stack, stack.enter_context(start())
    yield _shared_cells[name][1]
    to_come = _modules_to_come.get(name, set())
    to_come.discard(module)
    if not to_come:
        stack, _ = _shared_cells.pop(name)
        stack.close()


@pytest.fixture(scope="module")
def printed_box_cell(request, tmp_path_factory):
    """A simulated cell with a printed box, for tests/test_cell_pick.py and tests/test_cell_backgrounds.py."""
    from tests.cell_fixtures import printed_box_cell as started

    yield from _shared_cell("printed_box_cell", request.module.__name__,
                            lambda: started(tmp_path_factory.mktemp("printed-box")))


@pytest.fixture(scope="module")
def red_box_cell(request, tmp_path_factory):
    """A simulated cell of the default scene (a red box), for tests/test_api.py and tests/test_cell_scan.py."""
    from tests.cell_fixtures import cell_config, running_cell

    yield from _shared_cell("red_box_cell", request.module.__name__,
                            lambda: running_cell(cell_config(tmp_path_factory.mktemp("red-box"), cell_id="red")))
