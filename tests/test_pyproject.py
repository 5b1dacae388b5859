"""The package list in pyproject.toml names every package of the tree (a regular install must not miss one)."""

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_every_package_directory_is_installed():
    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    on_disk = {str(p.parent.relative_to(ROOT)).replace("/", ".")
               for top in ("edge", "host", "firmware_sim") for p in (ROOT / top).rglob("__init__.py")}
    assert on_disk - listed == set(), "packages missing from pyproject.toml (a `pip install .` would lack them)"
    assert listed - on_disk - {"thermotouch_models"} == set(), "pyproject.toml lists packages that do not exist"
