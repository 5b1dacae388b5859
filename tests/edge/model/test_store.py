import hashlib
import os
import shutil
from pathlib import Path

import pytest

from tests.support.bundles import (
    make_arrays,
    make_golden,
    manifest_extra,
    npz_bytes,
    write_raw_bundle,
)
from edge.estimation.estimate import mlp_golden_check
from edge.model import bundle as B
from edge.storage import durable
from edge.model.store import InstallError, ModelStore, ModelStoreError
from edge.security.policy import UpdatePolicy
from tests.support.killpoints import work_root

pytestmark = pytest.mark.slow

#: These tests are about atomicity and verification, not authentication (tests/edge/model/test_store_signed.py).
DEV_POLICY = UpdatePolicy(allow_unsigned=True)


def _sha(b: bytes) -> str:
    return hashlib.sha256(b).hexdigest()


@pytest.fixture(scope="module")
def blobs(tmp_path_factory):
    """Three distinct valid bundles (A, B, C) as transport blobs, a factory bundle, a bad one."""
    d = tmp_path_factory.mktemp("src")
    out = {}
    for i, tag in enumerate("ABC"):
        arrays = make_arrays(seed=10 + i, hidden=(12, 5))
        b = B.write_bundle(d / tag, arrays, make_golden(arrays), manifest_extra(tag), golden_check=mlp_golden_check)
        out[tag] = (B.bundle_to_bytes(b.path), b.sha256)
    arrays = make_arrays(seed=99, hidden=(12, 5))
    out["factory_path"] = B.write_bundle(d / "factory", arrays, make_golden(arrays), manifest_extra("factory"), golden_check=mlp_golden_check).path
    # Valid container and hashes, but golden vectors that do not reproduce.
    arrays = make_arrays(seed=5, hidden=(12, 5))
    g = make_golden(arrays)
    g["mlp_outputs"] = g["mlp_outputs"] + 0.01
    bad = write_raw_bundle(d / "bad", npz_bytes(arrays), npz_bytes(g))
    out["BAD"] = (B.pack_entries([(n.encode(), (bad / n).read_bytes()) for n in B.BUNDLE_FILES]), None)
    return out


def _install(store, blobs, tag):
    blob = blobs[tag][0]
    return store.install(blob, _sha(blob), len(blob))


def test_empty_store_without_factory_has_no_model(tmp_path):
    store = ModelStore(tmp_path / "store", golden_check=mlp_golden_check, policy=DEV_POLICY)
    with pytest.raises(ModelStoreError, match="no usable model"):
        store.current()
    assert any("no pointer" in e for e in store.boot_errors)


def test_factory_used_until_first_install(tmp_path, blobs):
    store = ModelStore(tmp_path / "s", blobs["factory_path"], golden_check=mlp_golden_check, policy=DEV_POLICY)
    assert store.current().model_version == "factory" and store.source == "factory"
    b = _install(store, blobs, "A")
    assert b.sha256 == blobs["A"][1] and store.current() is b and store.source == "current"
    assert not (tmp_path / "s" / "previous").exists()  # factory is not recorded as previous


def test_install_persists_and_keeps_previous(tmp_path, blobs):
    root = tmp_path / "s"
    store = ModelStore(root, blobs["factory_path"], golden_check=mlp_golden_check, policy=DEV_POLICY)
    _install(store, blobs, "A")
    _install(store, blobs, "B")
    assert (root / "current").read_text() == blobs["B"][1] + "\n"
    assert (root / "previous").read_text() == blobs["A"][1] + "\n"
    fresh = ModelStore(root, blobs["factory_path"], golden_check=mlp_golden_check, policy=DEV_POLICY)
    assert fresh.current().sha256 == blobs["B"][1] and fresh.source == "current"
    _install(fresh, blobs, "C")
    # Only current and previous are kept.
    assert sorted(os.listdir(root / "bundles")) == sorted([blobs["B"][1], blobs["C"][1]])
    assert os.listdir(root / "tmp") == []


def test_reinstall_same_bundle_is_harmless(tmp_path, blobs):
    store = ModelStore(tmp_path / "s", golden_check=mlp_golden_check, policy=DEV_POLICY)
    _install(store, blobs, "A")
    _install(store, blobs, "B")
    b = _install(store, blobs, "B")
    assert b.sha256 == blobs["B"][1]
    assert (tmp_path / "s" / "previous").read_text().strip() == blobs["A"][1]


@pytest.mark.parametrize(
    "mutate,match",
    [
        (lambda blob: (blob, "0" * 64, None), "blob sha256 mismatch"),
        (lambda blob: (blob, _sha(blob), len(blob) + 1), "blob size mismatch"),
        (lambda blob: (blob, "xyz", None), "expected_sha256"),
        (lambda blob: (blob[:-40] + blob[-32:], _sha(blob[:-40] + blob[-32:]), None), "checksum"),
        (lambda blob: (b"garbage" * 10, _sha(b"garbage" * 10), None), "magic"),
    ],
)
def test_bad_uploads_leave_current_untouched(tmp_path, blobs, mutate, match):
    root = tmp_path / "s"
    store = ModelStore(root, golden_check=mlp_golden_check, policy=DEV_POLICY)
    _install(store, blobs, "A")
    data, sha, size = mutate(blobs["B"][0])
    with pytest.raises(InstallError, match=match):
        store.install(data, sha, size)
    assert store.current().sha256 == blobs["A"][1]
    assert ModelStore(root, golden_check=mlp_golden_check, policy=DEV_POLICY).current().sha256 == blobs["A"][1]
    assert os.listdir(root / "bundles") == [blobs["A"][1]] and os.listdir(root / "tmp") == []


def test_rollback_on_bad_golden(tmp_path, blobs):
    root = tmp_path / "s"
    store = ModelStore(root, golden_check=mlp_golden_check, policy=DEV_POLICY)
    _install(store, blobs, "A")
    blob = blobs["BAD"][0]
    with pytest.raises(InstallError, match="golden vectors do not reproduce") as ei:
        store.install(blob, _sha(blob))
    assert isinstance(ei.value.__cause__, B.GoldenMismatchError)
    assert store.current().sha256 == blobs["A"][1]
    assert (root / "current").read_text().strip() == blobs["A"][1]
    assert not (root / "previous").exists()
    assert os.listdir(root / "bundles") == [blobs["A"][1]] and os.listdir(root / "tmp") == []


def test_store_level_golden_check_is_applied(tmp_path, blobs):
    store = ModelStore(tmp_path / "s", golden_check=lambda b, g: 1.0, policy=DEV_POLICY)
    with pytest.raises(InstallError, match="golden"):
        _install(store, blobs, "A")


def _corrupt_bundle(root: Path, sha: str) -> None:
    p = root / "bundles" / sha / "arrays.npz"
    data = bytearray(p.read_bytes())
    data[200] ^= 0x55
    p.write_bytes(bytes(data))


@pytest.mark.parametrize("how", ["garbage pointer", "empty pointer", "corrupt bundle", "missing bundle"])
def test_boot_falls_back_to_previous(tmp_path, blobs, how):
    root = tmp_path / "s"
    store = ModelStore(root, blobs["factory_path"], golden_check=mlp_golden_check, policy=DEV_POLICY)
    _install(store, blobs, "A")
    _install(store, blobs, "B")
    if how == "garbage pointer":
        (root / "current").write_bytes(b"\x00\xffnot a hash")
    elif how == "empty pointer":
        (root / "current").write_bytes(b"")
    elif how == "corrupt bundle":
        _corrupt_bundle(root, blobs["B"][1])
    else:
        shutil.rmtree(root / "bundles" / blobs["B"][1])
    fresh = ModelStore(root, blobs["factory_path"], golden_check=mlp_golden_check, policy=DEV_POLICY)
    assert fresh.current().sha256 == blobs["A"][1]
    assert fresh.source == "previous" and fresh.boot_errors and fresh.boot_errors[0].startswith("current:")


def test_boot_falls_back_to_factory_then_fails(tmp_path, blobs):
    root = tmp_path / "s"
    store = ModelStore(root, blobs["factory_path"], golden_check=mlp_golden_check, policy=DEV_POLICY)
    _install(store, blobs, "A")
    _install(store, blobs, "B")
    _corrupt_bundle(root, blobs["A"][1])
    _corrupt_bundle(root, blobs["B"][1])
    fresh = ModelStore(root, blobs["factory_path"], golden_check=mlp_golden_check, policy=DEV_POLICY)
    assert fresh.current().model_version == "factory" and fresh.source == "factory"
    assert len(fresh.boot_errors) == 2
    with pytest.raises(ModelStoreError, match="sha256 mismatch for arrays.npz"):
        ModelStore(root, tmp_path / "no_such_factory", golden_check=mlp_golden_check, policy=DEV_POLICY).current()
    # Installing over a broken store works and does not record the broken bundle as previous.
    b = _install(fresh, blobs, "C")
    assert ModelStore(root, golden_check=mlp_golden_check, policy=DEV_POLICY).current().sha256 == b.sha256


def test_pointer_to_wrong_identity_is_refused(tmp_path, blobs):
    root = tmp_path / "s"
    store = ModelStore(root, blobs["factory_path"], golden_check=mlp_golden_check, policy=DEV_POLICY)
    _install(store, blobs, "A")
    _install(store, blobs, "B")
    # Make the "B" directory hold A's files: hashes are fine but the identity is not B.
    dirb = root / "bundles" / blobs["B"][1]
    shutil.rmtree(dirb)
    shutil.copytree(root / "bundles" / blobs["A"][1], dirb)
    fresh = ModelStore(root, golden_check=mlp_golden_check, policy=DEV_POLICY)
    assert fresh.current().sha256 == blobs["A"][1] and fresh.source == "previous"
    assert "identity" in fresh.boot_errors[0]


def test_rollback(tmp_path, blobs):
    root = tmp_path / "s"
    store = ModelStore(root, golden_check=mlp_golden_check, policy=DEV_POLICY)
    with pytest.raises(ModelStoreError, match="no previous"):
        store.rollback()
    _install(store, blobs, "A")
    _install(store, blobs, "B")
    assert store.rollback().sha256 == blobs["A"][1]
    assert ModelStore(root, golden_check=mlp_golden_check, policy=DEV_POLICY).current().sha256 == blobs["A"][1]
    assert (root / "previous").read_text().strip() == blobs["B"][1]
    st = ModelStore(root, golden_check=mlp_golden_check, policy=DEV_POLICY).status()
    assert st["source"] == "current" and st["model_version"] == "A"


def test_startup_removes_stale_staging(tmp_path, blobs):
    root = tmp_path / "s"
    store = ModelStore(root, golden_check=mlp_golden_check, policy=DEV_POLICY)
    _install(store, blobs, "A")
    (root / "tmp" / "upload-dead").mkdir()
    (root / ".current.tmp123").write_text("junk")
    ModelStore(root, golden_check=mlp_golden_check, policy=DEV_POLICY)
    assert os.listdir(root / "tmp") == [] and not (root / ".current.tmp123").exists()


def test_startup_removes_bundles_no_pointer_names(tmp_path, blobs):
    """A flash killed after its bundle moved into bundles/ (or mid-collection) leaves it unreferenced.

    Found by tests/edge/service/test_kill_points.py: such bundles survived every restart until the
    next successful install.
    """
    root = tmp_path / "s"
    store = ModelStore(root, golden_check=mlp_golden_check, policy=DEV_POLICY)
    _install(store, blobs, "A")
    _install(store, blobs, "B")
    whole = root / "bundles" / blobs["C"][1]
    shutil.copytree(root / "bundles" / blobs["A"][1], whole)  # moved in, pointer not yet written
    half = root / "bundles" / ("e" * 64)
    shutil.copytree(root / "bundles" / blobs["A"][1], half)
    (half / "manifest.json").unlink()  # the collection was killed after its first unlink
    fresh = ModelStore(root, golden_check=mlp_golden_check, policy=DEV_POLICY)
    assert sorted(os.listdir(root / "bundles")) == sorted([blobs["A"][1], blobs["B"][1]])
    assert fresh.current().sha256 == blobs["B"][1]


def test_startup_keeps_bundles_when_current_is_lost(tmp_path, blobs):
    root = tmp_path / "s"
    store = ModelStore(root, golden_check=mlp_golden_check, policy=DEV_POLICY)
    _install(store, blobs, "A")
    (root / "current").unlink()
    ModelStore(root, golden_check=mlp_golden_check, policy=DEV_POLICY)
    assert os.listdir(root / "bundles") == [blobs["A"][1]]  # for a person to look at, not collected


# ------------------------------------------------------------------ power cut at every step


class PowerCut(BaseException):
    """Not an Exception: no cleanup handler may run after the power is gone."""


_PRIMITIVES = ("write_new_file", "fsync_dir", "make_dir", "replace", "rename_dir", "remove_tree")


def _arm(mp, crash_at: int | None, log: list):
    """Patch every durable primitive; from call number ``crash_at`` on, the power is off.

    The interrupted call does partial damage where that is possible: a torn file write, a
    partly deleted tree.
    """
    originals = {n: getattr(durable, n) for n in _PRIMITIVES}

    def wrap(name):
        def fn(*args):
            idx = len(log)
            log.append((name, [str(a) for a in args]))
            if crash_at is not None and idx >= crash_at:
                if idx == crash_at and name == "write_new_file":
                    Path(args[0]).write_bytes(bytes(args[1])[: len(args[1]) // 2])
                elif idx == crash_at and name == "remove_tree" and Path(args[0]).is_dir():
                    files = sorted(p for p in Path(args[0]).rglob("*") if p.is_file())
                    if files:
                        files[0].unlink()
                raise PowerCut(f"power cut at step {idx} ({name})")
            return originals[name](*args)

        return fn

    for n in _PRIMITIVES:
        mp.setattr(durable, n, wrap(n))
    return originals


@pytest.fixture
def no_disk_flush(monkeypatch):
    # The crash tests exercise the order of steps, which an in-process test can observe; the
    # flushes themselves cannot be observed here and only cost wall time.
    monkeypatch.setattr(os, "fsync", lambda fd: None)


@pytest.fixture
def scratch(tmp_path):
    """The power-cut tests' stores, on tmpfs when there is one. The power cut is simulated at the
    durable layer and fsync is stubbed (``no_disk_flush``), so the file system plays no part; on a
    disk, deleting each point's bundles only waits for the device."""
    with work_root(tmp_path) as d:
        yield d


def _store_with(root, blobs, tags):
    store = ModelStore(root, blobs["factory_path"], golden_check=mlp_golden_check, policy=DEV_POLICY)
    for t in tags:
        _install(store, blobs, t)
    return store


def _booted_copy(template, root, blobs):
    """A store booted on a copy of ``template`` (a store the earlier installs left, built once a test).

    The same files as installing the history again at every point, without re-verifying and
    re-writing its bundles each time; the install under test starts from a store that has just
    booted, and looks its active model up the way it does after any boot.
    """
    shutil.copytree(template, root)
    return ModelStore(root, blobs["factory_path"], golden_check=mlp_golden_check, policy=DEV_POLICY)


@pytest.mark.parametrize("history", [(), ("A",), ("A", "B")], ids=["first-install", "second", "third"])
def test_power_cut_at_every_step_leaves_a_working_model(scratch, blobs, no_disk_flush, history):
    new_tag = "C"
    before_sha = blobs[history[-1]][1] if history else None
    template = scratch / "template"
    _store_with(template, blobs, history)
    # Dry run to count the durable steps of one install.
    log: list = []
    store = _booted_copy(template, scratch / "dry", blobs)
    with pytest.MonkeyPatch.context() as mp:
        _arm(mp, None, log)
        _install(store, blobs, new_tag)
    n_steps = len(log)
    assert n_steps >= 8 and any(name == "replace" for name, _ in log)

    outcomes = []
    for i in range(n_steps):
        root = scratch / f"crash{i}"
        store = _booted_copy(template, root, blobs)
        with pytest.MonkeyPatch.context() as mp, pytest.raises(PowerCut):
            _arm(mp, i, [])
            _install(store, blobs, new_tag)
        # Reboot: a new process sees whatever reached the disk.
        rebooted = ModelStore(root, blobs["factory_path"], golden_check=mlp_golden_check, policy=DEV_POLICY)
        b = rebooted.current()
        assert b.sha256 in {before_sha, blobs[new_tag][1]} or (before_sha is None and rebooted.source == "factory")
        if before_sha is not None:
            assert rebooted.source in ("current", "previous"), (i, rebooted.boot_errors)
            assert rebooted.source == "current", f"step {i}: current pointer unusable: {rebooted.boot_errors}"
        outcomes.append("new" if b.sha256 == blobs[new_tag][1] else "old")
        # The store is still usable: the install can be retried.
        assert _install(rebooted, blobs, new_tag).sha256 == blobs[new_tag][1]
        assert ModelStore(root, golden_check=mlp_golden_check, policy=DEV_POLICY).current().sha256 == blobs[new_tag][1]
        shutil.rmtree(root)
    # Monotone: once the switch happened, later crashes keep the new model.
    assert outcomes == sorted(outcomes, key=lambda o: o == "new")
    assert outcomes[0] == "old" and "new" in outcomes


def test_power_cut_during_rollback(scratch, blobs, no_disk_flush):
    template = scratch / "template"
    _store_with(template, blobs, ("A", "B"))
    log: list = []
    store = _booted_copy(template, scratch / "dry", blobs)
    with pytest.MonkeyPatch.context() as mp:
        _arm(mp, None, log)
        store.rollback()
    for i in range(len(log)):
        root = scratch / f"rb{i}"
        store = _booted_copy(template, root, blobs)
        with pytest.MonkeyPatch.context() as mp, pytest.raises(PowerCut):
            _arm(mp, i, [])
            store.rollback()
        rebooted = ModelStore(root, golden_check=mlp_golden_check, policy=DEV_POLICY)
        assert rebooted.current().sha256 in {blobs["A"][1], blobs["B"][1]}
        assert rebooted.source == "current"
        shutil.rmtree(root)
