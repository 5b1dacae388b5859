import hashlib
import io
import json
import os
import struct
import zipfile

import numpy as np
import pytest

from tests.support.bundles import (
    make_arrays,
    make_golden,
    manifest_extra,
    npz_bytes,
    reseal,
    write_raw_bundle,
)
from edge.estimation.mlp import MLP
from edge.estimation.estimate import mlp_golden_check
from edge.model import bundle as B
from edge.model.schema import SCHEMAS, ArraySpec, declare_array


@pytest.fixture(scope="module")
def arrays():
    return make_arrays()


@pytest.fixture(scope="module")
def golden(arrays):
    return make_golden(arrays)


@pytest.fixture
def good(tmp_path, arrays, golden):
    return B.write_bundle(tmp_path / "good", arrays, golden, manifest_extra(), golden_check=mlp_golden_check).path


def _hostile(tmp_path, arrays, golden, name="bad", **kw):
    return write_raw_bundle(tmp_path / name, npz_bytes(arrays, **kw), npz_bytes(golden))


# ------------------------------------------------------------------ round trip


def test_round_trip(good, arrays, golden):
    b = B.load_bundle(good, golden_check=mlp_golden_check)
    assert set(b.arrays) == set(arrays)
    for k, v in arrays.items():
        np.testing.assert_array_equal(b.arrays[k], v)
        assert b.arrays[k].dtype == np.asarray(v).dtype
    np.testing.assert_array_equal(b.golden["mlp_outputs"], golden["mlp_outputs"])
    assert b.sha256 == hashlib.sha256((good / "manifest.json").read_bytes()).hexdigest()
    m = b.manifest
    assert m["schema_version"] == 1 and m["model_version"] == "1.0"
    assert m["metrics"] == {"r2": 0.99, "mape": 0.05}
    assert m["files"]["arrays.npz"]["size"] == (good / "arrays.npz").stat().st_size
    assert dict(b.dims) == {"n_features": 8, "n_components": 2, "mlp_d1": 100, "mlp_d2": 20, "n_golden": 16}
    assert sorted(os.listdir(good.parent)) == ["good"]  # no temp dirs left behind
    np.testing.assert_array_equal(MLP.from_arrays(b.arrays).predict(golden["mlp_inputs"]), golden["mlp_outputs"])


def test_loaded_bundle_is_read_only(good):
    b = B.load_bundle(good, golden_check=mlp_golden_check)
    with pytest.raises(ValueError):
        b.arrays["x_mean"][0] = 1.0
    with pytest.raises(TypeError):
        b.arrays["x_mean"] = np.zeros(8)
    b.manifest["model_version"] = "hacked"
    assert b.model_version == "1.0"


def test_fortran_ordered_members_load_as_their_values(tmp_path, arrays, golden):
    # The loader builds each array from the bytes after the header it checked, so it must honour
    # the header's order as np.load would; loaded twice, the second time from headers it has
    # parsed before. A big-endian member keeps its byte order and is refused by name.
    odd = {k: np.asfortranarray(v) if np.ndim(v) == 2 else v for k, v in arrays.items()}
    path = _hostile(tmp_path, odd, golden)
    with zipfile.ZipFile(path / "arrays.npz") as zf:
        assert b"'fortran_order': True" in zf.read("mlp_W0.npy")[:128]
    for _ in range(2):
        b = B.load_bundle(path, golden_check=mlp_golden_check)
        for k, v in arrays.items():
            np.testing.assert_array_equal(b.arrays[k], v)
            assert b.arrays[k].flags.c_contiguous and not b.arrays[k].flags.writeable
    swapped = _hostile(tmp_path, dict(arrays, x_mean=np.asarray(arrays["x_mean"]).astype(">f8")), golden, "be")
    with pytest.raises(B.DtypeError, match="'x_mean' expected dtype float64, got >f8"):
        B.load_bundle(swapped, golden_check=mlp_golden_check)


def test_writer_is_deterministic_and_refuses_overwrite(tmp_path, good, arrays, golden):
    again = B.write_bundle(tmp_path / "again", arrays, golden, manifest_extra(), golden_check=mlp_golden_check)
    assert again.sha256 == B.load_bundle(good, golden_check=mlp_golden_check).sha256
    with pytest.raises(FileExistsError, match="overwrite"):
        B.write_bundle(good, arrays, golden, manifest_extra(), golden_check=mlp_golden_check)
    b2 = B.write_bundle(good, arrays, golden, manifest_extra("2.0"), overwrite=True, golden_check=mlp_golden_check)
    assert B.load_bundle(good, golden_check=mlp_golden_check).model_version == "2.0" and b2.path == good
    assert sorted(os.listdir(tmp_path)) == ["again", "good"]


def test_writer_refuses_bad_content_and_writes_nothing(tmp_path, arrays, golden):
    bad = dict(arrays, x_scale=np.ones(7))
    with pytest.raises(B.ShapeError, match="x_scale"):
        B.write_bundle(tmp_path / "b", bad, golden, manifest_extra(), golden_check=mlp_golden_check)
    wrong_golden = dict(golden, mlp_outputs=golden["mlp_outputs"] + 1.0)
    with pytest.raises(B.GoldenMismatchError):
        B.write_bundle(tmp_path / "b", arrays, wrong_golden, manifest_extra(), golden_check=mlp_golden_check)
    with pytest.raises(B.DtypeError, match="float32"):
        B.write_bundle(tmp_path / "b", dict(arrays, x_mean=np.zeros(8, np.float32)), golden, manifest_extra(), golden_check=mlp_golden_check)
    with pytest.raises(ValueError, match="manifest_extra"):
        B.write_bundle(tmp_path / "b", arrays, golden, dict(manifest_extra(), metrics={"r2": float("nan")}), golden_check=mlp_golden_check)
    assert os.listdir(tmp_path) == []


def test_unicode_library_tables_round_trip(tmp_path, arrays, golden):
    lib = {
        "lib_effusivity": np.array([1500.0, 20000.0]),
        "lib_k": np.array([1.1, 200.0]),
        "lib_rho_c": np.array([2.0e6, 2.4e6]),
        "lib_names": np.array(["tempered glass", "aluminium 6061"], dtype="<U64"),
        "lib_class": np.array(["glass", "metal"]),
    }
    b = B.write_bundle(tmp_path / "lib", {**arrays, **lib}, golden, manifest_extra(), golden_check=mlp_golden_check)
    assert list(B.load_bundle(b.path, golden_check=mlp_golden_check).arrays["lib_names"]) == ["tempered glass", "aluminium 6061"]
    assert b.dims["n_materials"] == 2


# ------------------------------------------------------------------ file-level refusals


@pytest.mark.parametrize("name", ["manifest.json", "arrays.npz", "golden.npz"])
def test_missing_file(good, name):
    (good / name).unlink()
    with pytest.raises(B.MissingFileError, match=name) as ei:
        B.load_bundle(good, golden_check=mlp_golden_check)
    assert ei.value.subject == name


@pytest.mark.parametrize("name", ["arrays.npz", "golden.npz"])
def test_flipped_byte_is_sha_mismatch_naming_file(good, name):
    p = good / name
    data = bytearray(p.read_bytes())
    data[len(data) // 2] ^= 0x01
    p.write_bytes(bytes(data))
    with pytest.raises(B.HashMismatchError, match=f"sha256 mismatch for {name}"):
        B.load_bundle(good, golden_check=mlp_golden_check)


def test_truncated_file(good):
    p = good / "arrays.npz"
    p.write_bytes(p.read_bytes()[:-100])
    with pytest.raises(B.HashMismatchError, match="size mismatch for arrays.npz"):
        B.load_bundle(good, golden_check=mlp_golden_check)
    reseal(good)  # even with a manifest that agrees, a truncated npz is refused as unreadable
    with pytest.raises(B.CorruptFileError, match="arrays.npz is truncated or not a readable npz"):
        B.load_bundle(good, golden_check=mlp_golden_check)


def test_garbage_npz_with_matching_hash(tmp_path, golden):
    path = write_raw_bundle(tmp_path / "g", b"this is not a zip file", npz_bytes(golden))
    with pytest.raises(B.CorruptFileError, match="arrays.npz"):
        B.load_bundle(path, golden_check=mlp_golden_check)


def test_member_data_shorter_than_header_says(tmp_path, arrays, golden):
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for k, v in arrays.items():
            npy = io.BytesIO()
            np.save(npy, v)
            raw = npy.getvalue()
            zf.writestr(k + ".npy", raw[:-8] if k == "x_mean" else raw)
    path = write_raw_bundle(tmp_path / "s", buf.getvalue(), npz_bytes(golden))
    with pytest.raises(B.CorruptFileError, match="'x_mean' holds"):
        B.load_bundle(path, golden_check=mlp_golden_check)


def test_symlinked_file_refused(good, tmp_path):
    target = tmp_path / "elsewhere.npz"
    target.write_bytes((good / "golden.npz").read_bytes())
    (good / "golden.npz").unlink()
    (good / "golden.npz").symlink_to(target)
    with pytest.raises(B.UnsafePathError, match="golden.npz is a symlink"):
        B.load_bundle(good, golden_check=mlp_golden_check)
    with pytest.raises(B.UnsafePathError):
        B.bundle_to_bytes(good)


# ------------------------------------------------------------------ manifest refusals


def _edit_manifest(path, fn):
    m = json.loads((path / "manifest.json").read_text())
    fn(m)
    (path / "manifest.json").write_text(json.dumps(m))


def test_unknown_schema_version(good):
    _edit_manifest(good, lambda m: m.update(schema_version=99))
    with pytest.raises(B.SchemaVersionError, match="unknown schema_version 99"):
        B.load_bundle(good, golden_check=mlp_golden_check)


@pytest.mark.parametrize(
    "text,match",
    [
        (b"{not json", "malformed JSON"),
        (b"\xff\xfe", "malformed JSON"),
        (b"[1, 2]", "top level"),
        (b'{"schema_version": NaN}', "malformed JSON"),
        (b'{"schema_version": "1"}', "schema_version"),
    ],
)
def test_malformed_manifest(good, text, match):
    (good / "manifest.json").write_bytes(text)
    with pytest.raises(B.ManifestError, match=match):
        B.load_bundle(good, golden_check=mlp_golden_check)


@pytest.mark.parametrize("key", ["metrics", "files", "training_set_sha256", "model_version", "created_utc"])
def test_manifest_missing_key(good, key):
    _edit_manifest(good, lambda m: m.pop(key))
    with pytest.raises(B.ManifestError, match=key):
        B.load_bundle(good, golden_check=mlp_golden_check)


def test_oversize_manifest(good):
    _edit_manifest(good, lambda m: m.update(padding="x" * 70_000))
    with pytest.raises(B.SizeLimitError, match="manifest.json is .* above the limit"):
        B.load_bundle(good, golden_check=mlp_golden_check)


# ------------------------------------------------------------------ array-level refusals


def test_wrong_shape_names_array_and_expected(tmp_path, arrays, golden):
    path = _hostile(tmp_path, dict(arrays, x_scale=np.ones(7)), golden)
    with pytest.raises(B.ShapeError) as ei:
        B.load_bundle(path, golden_check=mlp_golden_check)
    msg = str(ei.value)
    assert "'x_scale'" in msg and "n_features=8" in msg and "got (7,)" in msg
    assert ei.value.subject == "x_scale"


def test_wrong_ndim(tmp_path, arrays, golden):
    path = _hostile(tmp_path, dict(arrays, feature_version=np.array([1], np.int64)), golden)
    with pytest.raises(B.ShapeError, match="'feature_version' expected 0-D"):
        B.load_bundle(path, golden_check=mlp_golden_check)


def test_mlp_layers_must_chain(tmp_path, arrays, golden):
    path = _hostile(tmp_path, dict(arrays, mlp_W1=np.ones((99, 20))), golden)
    with pytest.raises(B.ShapeError, match="'mlp_W1' expected shape \\(mlp_d1=100, mlp_d2\\)"):
        B.load_bundle(path, golden_check=mlp_golden_check)
    path = _hostile(tmp_path, dict(arrays, mlp_W2=np.ones((20, 2)), mlp_b2=np.ones(2)), golden, name="two_out")
    with pytest.raises(B.ShapeError, match="'mlp_W2'"):
        B.load_bundle(path, golden_check=mlp_golden_check)


def test_golden_shape_consistent_with_model(tmp_path, arrays, golden):
    g = dict(golden, mlp_inputs=np.ones((16, 3)))
    path = write_raw_bundle(tmp_path / "g", npz_bytes(arrays), npz_bytes(g))
    with pytest.raises(B.ShapeError, match="golden.npz: array 'mlp_inputs' expected shape \\(n_golden=16, n_components=2\\)"):
        B.load_bundle(path, golden_check=mlp_golden_check)


@pytest.mark.parametrize(
    "name,value,match",
    [
        ("x_mean", np.zeros(8, np.float32), "'x_mean' expected dtype float64, got float32"),
        ("feature_version", np.array(1, np.int32), "'feature_version' expected dtype int64, got int32"),
        ("x_scale", np.ones(8, ">f8"), "'x_scale' expected dtype float64"),
        ("lib_names", np.array(["a" * 100] * 2), "at most 64 characters"),
    ],
)
def test_wrong_dtype(tmp_path, arrays, golden, name, value, match):
    extra = {}
    if name == "lib_names":
        extra = {
            "lib_effusivity": np.ones(2), "lib_k": np.ones(2), "lib_rho_c": np.ones(2),
            "lib_class": np.array(["x", "y"]),
        }
    path = _hostile(tmp_path, {**arrays, **extra, name: value}, golden)
    with pytest.raises(B.DtypeError, match=match):
        B.load_bundle(path, golden_check=mlp_golden_check)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_names_array(tmp_path, arrays, golden, bad):
    pc = arrays["pca_components"].copy()
    pc[1, 3] = bad
    path = _hostile(tmp_path, dict(arrays, pca_components=pc), golden)
    with pytest.raises(B.NonFiniteError, match="'pca_components' contains 1 NaN/inf"):
        B.load_bundle(path, golden_check=mlp_golden_check)


def test_non_finite_golden(tmp_path, arrays, golden):
    g = dict(golden, mlp_outputs=np.full(16, np.nan))
    path = write_raw_bundle(tmp_path / "g", npz_bytes(arrays), npz_bytes(g))
    with pytest.raises(B.NonFiniteError, match="golden.npz: array 'mlp_outputs'"):
        B.load_bundle(path, golden_check=mlp_golden_check)


def test_object_array_refused_without_unpickling(tmp_path, arrays, golden):
    # The hostile file is written with pickle allowed; the loader must never unpickle it.
    hostile = dict(arrays, x_mean=np.array([{"evil": 1}] * 8, dtype=object))
    path = _hostile(tmp_path, hostile, golden, allow_pickle=True)
    with pytest.raises(B.ObjectArrayError, match="'x_mean' has dtype object"):
        B.load_bundle(path, golden_check=mlp_golden_check)


def test_unknown_and_missing_arrays(tmp_path, arrays, golden):
    p1 = _hostile(tmp_path, dict(arrays, surprise=np.zeros(3)), golden, name="u")
    with pytest.raises(B.UnknownArrayError, match="unknown array 'surprise'"):
        B.load_bundle(p1, golden_check=mlp_golden_check)
    p2 = _hostile(tmp_path, dict(arrays, mlp_W3=np.ones((1, 1)), mlp_b3=np.ones(1)), golden, name="extra_layer")
    with pytest.raises(B.UnknownArrayError, match="'mlp_(W|b)3' is beyond the 3 layer"):
        B.load_bundle(p2, golden_check=mlp_golden_check)
    missing = {k: v for k, v in arrays.items() if k != "x_mean"}
    p3 = _hostile(tmp_path, missing, golden, name="m")
    with pytest.raises(B.MissingArrayError, match="missing required array 'x_mean'"):
        B.load_bundle(p3, golden_check=mlp_golden_check)
    p4 = _hostile(tmp_path, dict(arrays, lib_k=np.ones(3)), golden, name="grp")
    with pytest.raises(B.MissingArrayError, match="group 'lib' is all-or-none"):
        B.load_bundle(p4, golden_check=mlp_golden_check)


@pytest.mark.parametrize(
    "name,value,match",
    [
        ("mlp_hidden_activation", np.array(9, np.int64), "outside the allowed codes"),
        ("y_transform", np.array(2, np.int64), "outside the allowed codes"),
        ("x_scale", np.zeros(8), "'x_scale' has value 0.0 below"),
        ("mlp_n_layers", np.array(40, np.int64), "'mlp_n_layers'"),
    ],
)
def test_value_range(tmp_path, arrays, golden, name, value, match):
    path = _hostile(tmp_path, dict(arrays, **{name: value}), golden)
    with pytest.raises(B.ValueRangeError, match=match):
        B.load_bundle(path, golden_check=mlp_golden_check)


def test_size_bounds(good):
    with pytest.raises(B.SizeLimitError, match="'mlp_W1' has 2000 elements"):
        B.load_bundle(good, limits=B.Limits(max_array_elements=1000), golden_check=mlp_golden_check)
    with pytest.raises(B.SizeLimitError, match="arrays total more than 10000 bytes"):
        B.load_bundle(good, limits=B.Limits(max_total_array_bytes=10_000), golden_check=mlp_golden_check)
    with pytest.raises(B.SizeLimitError, match="arrays.npz is .* above the limit"):
        B.load_bundle(good, limits=B.Limits(max_npz_bytes=1000), golden_check=mlp_golden_check)


def test_spec_max_elements(tmp_path, arrays, golden):
    path = _hostile(tmp_path, dict(arrays, prior_coef=np.zeros(1_000_001)), golden)
    with pytest.raises(B.SizeLimitError, match="'prior_coef' has 1000001 elements, above its limit"):
        B.load_bundle(path, golden_check=mlp_golden_check)


def test_lying_header_does_not_allocate(tmp_path, arrays, golden):
    # Header claims 10^12 float64s; the loader must refuse from the header, not try to allocate.
    header = {"descr": "<f8", "fortran_order": False, "shape": (10**12,)}
    npy = io.BytesIO()
    np.lib.format.write_array_header_1_0(npy, header)
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        zf.writestr("prior_coef.npy", npy.getvalue() + b"\0" * 64)
        for k, v in arrays.items():
            one = io.BytesIO()
            np.save(one, v)
            zf.writestr(k + ".npy", one.getvalue())
    path = write_raw_bundle(tmp_path / "lie", buf.getvalue(), npz_bytes(golden))
    with pytest.raises(B.SizeLimitError, match="'prior_coef' has 1000000000000 elements"):
        B.load_bundle(path, golden_check=mlp_golden_check)


def test_bad_member_names(tmp_path, golden):
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        zf.writestr("../escape.npy", b"x")
    path = write_raw_bundle(tmp_path / "n", buf.getvalue(), npz_bytes(golden))
    with pytest.raises(B.CorruptFileError, match="unexpected member '../escape.npy'"):
        B.load_bundle(path, golden_check=mlp_golden_check)


# ------------------------------------------------------------------ golden check


def test_golden_mismatch(tmp_path, arrays, golden):
    g = dict(golden, mlp_outputs=golden["mlp_outputs"] * (1 + 1e-6))
    path = write_raw_bundle(tmp_path / "g", npz_bytes(arrays), npz_bytes(g))
    with pytest.raises(B.GoldenMismatchError, match="max relative error 1e-06 > tolerance 1e-09"):
        B.load_bundle(path, golden_check=mlp_golden_check)
    assert B.load_bundle(path, golden_rtol=1e-5, golden_check=mlp_golden_check).sha256  # looser tolerance accepts
    assert B.load_bundle(path, golden_check=None).sha256  # inspection without check


def test_pluggable_golden_check(good):
    seen = {}

    def check(bundle, golden):
        seen["keys"] = sorted(golden)
        return 0.5

    with pytest.raises(B.GoldenMismatchError, match="'check'"):
        B.load_bundle(good, golden_check=check)
    assert seen["keys"] == ["mlp_inputs", "mlp_outputs"]
    assert B.load_bundle(good, golden_check=lambda b, g: 0.0).sha256

    def broken(bundle, golden):
        raise KeyError("pipeline_inputs")

    with pytest.raises(B.GoldenMismatchError, match="failed: KeyError"):
        B.load_bundle(good, golden_check=broken)
    with pytest.raises(B.GoldenMismatchError):
        B.load_bundle(good, golden_check=lambda b, g: float("nan"))


def test_max_relative_error_floor():
    exp = np.array([1.0, 1e-12])
    assert B.max_relative_error(exp + 1e-15, exp) < 1e-11  # near-zero entry uses the floor
    assert B.max_relative_error(np.array([1.0]), np.array([1.0, 2.0])) == np.inf
    assert B.max_relative_error(np.array([np.nan, 1.0]), exp) == np.inf


# ------------------------------------------------------------------ schema extension


def test_declare_array_extends_schema(tmp_path, arrays, golden):
    spec = ArraySpec("f", ("n_features",), required=False, doc="test-only")
    declare_array("zz_test_extra", spec)
    try:
        declare_array("zz_test_extra", spec)  # idempotent
        with pytest.raises(ValueError, match="already declared"):
            declare_array("zz_test_extra", ArraySpec("i", ()))
        b = B.write_bundle(tmp_path / "ext", dict(arrays, zz_test_extra=np.ones(8)), golden, manifest_extra(), golden_check=mlp_golden_check)
        assert b.arrays["zz_test_extra"].shape == (8,)
        with pytest.raises(B.ShapeError, match="zz_test_extra"):
            B.write_bundle(tmp_path / "ext2", dict(arrays, zz_test_extra=np.ones(3)), golden, manifest_extra(), golden_check=mlp_golden_check)
    finally:
        del SCHEMAS[1].arrays["zz_test_extra"]


# ------------------------------------------------------------------ transport blob


def test_blob_round_trip(good, tmp_path):
    blob = B.bundle_to_bytes(good)
    assert blob.startswith(b"TTBUNDLE") and blob == B.bundle_to_bytes(good)
    dest = B.bundle_from_bytes(blob, tmp_path / "copy")
    assert B.load_bundle(dest, golden_check=mlp_golden_check).sha256 == B.load_bundle(good, golden_check=mlp_golden_check).sha256
    with pytest.raises(FileExistsError):
        B.bundle_from_bytes(blob, dest)
    link = tmp_path / "link"
    link.symlink_to(tmp_path / "nowhere")
    with pytest.raises(FileExistsError):
        B.bundle_from_bytes(blob, link)  # a dangling symlink at dest is not followed


def _entries(good):
    return [(n.encode(), (good / n).read_bytes()) for n in B.BUNDLE_FILES]


@pytest.mark.parametrize(
    "bad_name", [b"../manifest.json", b"/etc/passwd", b"sub/arrays.npz", b"..\\golden.npz", b".hidden"]
)
def test_blob_path_traversal(good, tmp_path, bad_name):
    entries = _entries(good)
    entries[1] = (bad_name, entries[1][1])
    with pytest.raises(B.UnsafePathError, match="path traversal"):
        B.bundle_from_bytes(B.pack_entries(entries), tmp_path / "x")
    assert not (tmp_path / "x").exists() and not (tmp_path.parent / "manifest.json").exists()


def test_blob_structure_refusals(good, tmp_path):
    e = _entries(good)
    with pytest.raises(B.UnsafePathError, match="'evil.txt' is not one of"):
        B.parse_blob(B.pack_entries([e[0], e[1], (b"evil.txt", b"x")]))
    with pytest.raises(B.TransportError, match="twice"):
        B.parse_blob(B.pack_entries([e[0], e[1], e[1]]))
    with pytest.raises(B.TransportError, match="holds 2 entries"):
        B.parse_blob(B.pack_entries(e[:2]))
    blob = B.pack_entries(e)
    with pytest.raises(B.HashMismatchError, match="checksum"):
        B.parse_blob(blob[:-1])
    flipped = bytearray(blob)
    flipped[100] ^= 0xFF
    with pytest.raises(B.HashMismatchError, match="checksum"):
        B.parse_blob(bytes(flipped))
    with pytest.raises(B.TransportError, match="magic"):
        B.parse_blob(b"NOTMAGIC" + blob[8:])
    body = B.pack_entries(e)[:-32] + b"junk"
    with pytest.raises(B.TransportError, match="trailing bytes"):
        B.parse_blob(body + hashlib.sha256(body).digest())
    with pytest.raises(B.TransportError, match="truncated"):
        B.parse_blob(b"TTB")


def test_blob_declared_oversize_entry(good):
    # Entry claims 2^60 bytes: refused from the length field, before any slicing/allocation.
    body = B.BLOB_MAGIC + struct.pack("<HH", 1, 3) + struct.pack("<H", 10) + b"arrays.npz" + struct.pack("<Q", 2**60)
    with pytest.raises(B.SizeLimitError, match="'arrays.npz' is 1152921504606846976 bytes"):
        B.parse_blob(body + hashlib.sha256(body).digest())
    with pytest.raises(B.SizeLimitError, match="transport blob is"):
        B.parse_blob(b"\0" * 5000, limits=B.Limits(max_manifest_bytes=10, max_npz_bytes=10))


def _settings():
    # Hypothesis imported where these run, not at collection in every xdist worker (see tests/edge/protocol/test_fuzz.py).
    from hypothesis import HealthCheck, settings

    return settings(max_examples=60, derandomize=True, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])


@pytest.mark.shares_import("hypothesis")
def test_fuzzed_arrays_npz_only_raises_bundle_errors(good, tmp_path):
    from hypothesis import given, strategies as st

    @_settings()
    @given(pos=st.integers(min_value=0), val=st.integers(1, 255))
    def prop(pos, val):
        # Corrupt one byte of a validly-hashed npz: the loader must refuse cleanly (or, if the byte
        # was irrelevant, load) -- never crash with another exception type.
        work = tmp_path / f"f{pos}_{val}"
        data = bytearray((good / "arrays.npz").read_bytes())
        data[pos % len(data)] ^= val
        write_raw_bundle(work, bytes(data), (good / "golden.npz").read_bytes())
        try:
            B.load_bundle(work, golden_check=mlp_golden_check)
        except B.BundleError:
            pass

    prop()


@pytest.mark.shares_import("hypothesis")
def test_fuzzed_blob_truncation(good):
    from hypothesis import given, strategies as st

    blob = B.bundle_to_bytes(good)

    @_settings()
    @given(cut=st.integers(min_value=0, max_value=40_000))
    def prop(cut):
        with pytest.raises(B.BundleError):
            B.parse_blob(blob[: cut % len(blob)])

    prop()


def test_a_kept_parse_serves_only_bytes_that_verify(good, arrays):
    """The loader keeps a verified file's parse (edge.model.loader._PARSED): a second load gives the same values,
    read-only; a file changed in place after that load (same size) is still refused on its hash, and the kept
    arrays are not handed out for it."""
    first = B.load_bundle(good, golden_check=mlp_golden_check)
    again = B.load_bundle(good, golden_check=mlp_golden_check)
    assert again.sha256 == first.sha256 and dict(again.dims) == dict(first.dims)
    for k, v in arrays.items():
        np.testing.assert_array_equal(again.arrays[k], v)
        assert not again.arrays[k].flags.writeable
    path = good / "arrays.npz"
    data = bytearray(path.read_bytes())
    data[-30] ^= 0xFF
    path.write_bytes(bytes(data))
    with pytest.raises(B.HashMismatchError, match="arrays.npz"):
        B.load_bundle(good, golden_check=mlp_golden_check)
