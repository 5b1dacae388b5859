"""Physics is tested against exact solutions and the shipped material library."""

import pytest

from edge.physics.materials import load_materials


@pytest.fixture(scope="module")
def lib():
    return load_materials()
