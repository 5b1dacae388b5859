"""The semantic self-check on the install path: self-consistent garbage is refused, the old model serves.

The broken bundles are copies of the shipped one with fresh hashes and golden vectors
(tests.support.bundles.broken_copy): only what they *decide* is wrong.
"""

import hashlib

import pytest

from edge.estimation.estimate import pipeline_golden_check
from edge.estimation.selfcheck import SemanticCheckError, semantic_check
from edge.model import bundle as B
from edge.model.store import InstallError, ModelStore
from edge.security.policy import UpdatePolicy
from tests.support.bundles import broken_copy
from thermotouch_models import DEFAULT_BUNDLE

DEV_POLICY = UpdatePolicy(allow_unsigned=True)  # this file is about what a bundle decides, not who signed it


@pytest.fixture(scope="module")
def broken(tmp_path_factory):
    d = tmp_path_factory.mktemp("broken")
    return {how: broken_copy(DEFAULT_BUNDLE, d / how, how) for how in ("permuted_names", "negated_output")}


def _blob(bundle):
    blob = B.bundle_to_bytes(bundle.path)
    return blob, hashlib.sha256(blob).hexdigest()


def test_shipped_bundle_passes_the_semantic_check():
    semantic_check(B.load_bundle(DEFAULT_BUNDLE, pipeline_golden_check))


@pytest.mark.parametrize("how, says", [("permuted_names", "library entry"), ("negated_output", "network's k")])
def test_self_consistent_garbage_is_refused_in_one_line_and_the_old_model_serves(tmp_path, broken, how, says):
    store = ModelStore(tmp_path / "store", DEFAULT_BUNDLE, golden_check=pipeline_golden_check,
                       semantic_check=semantic_check, policy=DEV_POLICY)
    before = store.current().sha256
    blob, sha = _blob(broken[how])
    with pytest.raises(InstallError) as ei:
        store.install(blob, sha, len(blob))
    msg = str(ei.value)
    assert "semantic self-check" in msg and says in msg and "\n" not in msg
    assert store.current().sha256 == before and store.source == "factory"
    assert not any((tmp_path / "store" / "bundles").iterdir())  # nothing stored, no pointer moved
    # Without the injected check the store accepts it: the hashes and golden vectors are consistent.
    assert ModelStore(tmp_path / "plain", golden_check=pipeline_golden_check, policy=DEV_POLICY).install(blob, sha, len(blob))


def test_the_reference_touch_alone_catches_swapped_names(monkeypatch):
    # pmma <-> tempered_glass swapped: the library check would catch the properties first, so it
    # is switched off here to prove the reference touch refuses it on its own.
    import numpy as np

    from edge.estimation import selfcheck

    b = B.load_bundle(DEFAULT_BUNDLE, pipeline_golden_check)
    arrays = dict(b.arrays)
    names = np.array(arrays["lib_names"])
    i, j = list(names).index("pmma"), list(names).index("tempered_glass")
    names[i], names[j] = names[j], names[i]
    arrays["lib_names"] = names

    class Fake:
        sha256 = "0" * 64

    Fake.arrays = arrays
    monkeypatch.setattr(selfcheck, "_check_library", lambda a: None)
    with pytest.raises(SemanticCheckError, match="names it"):
        semantic_check(Fake())


def test_duplicate_names_are_refused():
    import numpy as np

    b = B.load_bundle(DEFAULT_BUNDLE, pipeline_golden_check)
    arrays = dict(b.arrays)
    names = np.array(arrays["lib_names"])
    names[1] = names[0]
    arrays["lib_names"] = names

    class Fake:
        sha256 = "0" * 64

    Fake.arrays = arrays
    with pytest.raises(SemanticCheckError, match="twice"):
        semantic_check(Fake())


def test_a_subset_library_without_the_references_passes():
    import numpy as np

    b = B.load_bundle(DEFAULT_BUNDLE, pipeline_golden_check)
    names = [str(n) for n in b.arrays["lib_names"]]
    keep = np.array([n not in ("pmma", "tempered_glass", "aisi_304") for n in names])
    arrays = dict(b.arrays)
    for k in ("lib_effusivity", "lib_k", "lib_rho_c", "lib_names", "lib_class"):
        arrays[k] = np.asarray(arrays[k])[keep]

    class Fake:
        sha256 = "0" * 64

    Fake.arrays = arrays
    semantic_check(Fake())
