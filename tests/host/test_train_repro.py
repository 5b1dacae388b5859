"""A seeded retrain is reproducible: same seed and recipe, bit-identical arrays (one BLAS thread)."""

import numpy as np
import pytest

from edge.physics.materials import MaterialLibrary, load_materials

NAMES = ("pmma", "tempered_glass", "aisi_304", "cork_board", "granite", "oak_cross_grain", "aluminium_alloy",
         "platinum", "plywood", "fused_silica")


@pytest.mark.slow  # two retrains
@pytest.mark.shares_import("sklearn")  # with the suite's other trainers on one worker (tests/support/schedule.py)
@pytest.mark.filterwarnings("ignore:lbfgs failed to converge")
def test_same_seed_same_arrays_even_with_the_training_set_regenerated(tmp_path, monkeypatch):
    from host.train import clear_fit_memo, train_bundle  # scikit-learn, 1.2 s: not at collection in every worker

    lib = load_materials()
    small = MaterialLibrary([lib.get(n) for n in NAMES])
    arrays = []
    for run in ("a", "b"):
        # A cache of its own per run: the training set is generated twice, not read back.
        monkeypatch.setenv("THERMOTOUCH_CACHE", str(tmp_path / f"cache-{run}"))
        clear_fit_memo()  # each run fits afresh (host.train keeps fits by their exact inputs)
        b, _ = train_bundle(tmp_path / run, quick=True, seed=3, lib=small, log=lambda s: None)
        arrays.append(b.arrays)
    a, b = arrays
    assert sorted(a) == sorted(b)
    for k in a:
        assert np.array_equal(a[k], b[k]), k
    # A different seed gives another network (the seed reaches the fit).
    c, _ = train_bundle(tmp_path / "c", quick=True, seed=4, lib=small, log=lambda s: None)
    assert not np.array_equal(c.arrays["mlp_W0"], a["mlp_W0"])


def test_noisy_training_set_does_not_depend_on_what_the_process_resampled_before():
    # The quick recipe has no noisy copies, so this is where resampling enters a training set.
    from edge.estimation import spline
    from host.dataset import DatasetSpec, generate

    lib = load_materials()
    small = MaterialLibrary([lib.get(n) for n in NAMES[:4]])
    spec = DatasetSpec(noisy_copies=1, levels_W_m3=DatasetSpec.levels_W_m3[::10])
    with spline._cache_lock:  # a process that has resampled nothing yet
        spline._operators.clear()
    first = generate(spec, small, cache=False)
    second = generate(spec, small, cache=False)  # now every time base is in the resampling cache
    assert first.noisy.any()
    assert np.array_equal(first.features, second.features)
