"""Shared fixtures; and the core runs here as the ``robocell`` command runs it, on one BLAS thread."""

import os

# As robocell/cli/main.py does, and before numpy is imported: the fit's small problems gain nothing from
# BLAS threads and lose much to them beside other work (the suite's core tests, and every child process
# the cell tests start through ``robocell``, then run alike).
for _variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")

import shutil  # noqa: E402

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
def printed_box_cell(tmp_path_factory):
    """One simulated cell with a printed box for tests/test_cell_pick.py and tests/test_cell_backgrounds.py:
    a cell's start is seconds of six processes' imports."""
    from tests.cell_fixtures import printed_box_cell as started

    with started(tmp_path_factory.mktemp("printed-box")) as cell:
        yield cell


@pytest.fixture(scope="session")
def red_box_cell(tmp_path_factory):
    """One simulated cell of the default scene (a red box) for tests/test_api.py and tests/test_cell_scan.py."""
    from tests.cell_fixtures import cell_config, running_cell

    with running_cell(cell_config(tmp_path_factory.mktemp("red-box"), cell_id="red")) as cell:
        yield cell
