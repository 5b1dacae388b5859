"""Fixtures shared by the edge tests of more than one package (the seam's estimation and recognition tests)."""

import pytest


@pytest.fixture(scope="session")
def estimator():
    """The shipped bundle's estimator (the seam's tests; session-scoped, so the modules share one)."""
    from edge.estimation.estimate import Estimator, pipeline_golden_check
    from edge.model.bundle import load_bundle
    from thermotouch_models import DEFAULT_BUNDLE

    return Estimator.from_bundle(load_bundle(DEFAULT_BUNDLE, golden_check=pipeline_golden_check))
