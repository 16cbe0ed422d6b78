import shutil

import pytest

from tests.bundles import write_sphere_bundle


@pytest.fixture(scope="session")
def sphere_bundle_template(tmp_path_factory):
    """A sphere bundle rendered once; tests get copies they may edit."""
    return write_sphere_bundle(tmp_path_factory.mktemp("template") / "sphere")


@pytest.fixture
def sphere_bundle(sphere_bundle_template, tmp_path):
    return shutil.copytree(sphere_bundle_template, tmp_path / "sphere")
