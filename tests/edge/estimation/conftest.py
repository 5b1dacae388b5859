"""Estimators are tested on a quick bundle trained once per module from the material library."""

import warnings

import pytest

from edge.estimation.estimate import Estimator


@pytest.fixture(scope="module")
def quick_bundle(tmp_path_factory):
    from host.train import train_bundle  # host-side training; the edge code under test never imports it

    out = tmp_path_factory.mktemp("b") / "bundle"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        bundle, metrics = train_bundle(out, quick=True, log=lambda s: None)
    return out, bundle, metrics


@pytest.fixture(scope="module")
def est(quick_bundle):
    return Estimator.from_bundle(quick_bundle[1])


@pytest.fixture(scope="session")
def records():
    """The seam's records (tests/support/seam_records.py), simulated once for the contract and the refusals."""
    from tests.support.seam_records import seam_records

    return seam_records()
