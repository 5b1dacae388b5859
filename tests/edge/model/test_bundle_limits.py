"""Bundle bounds from the device's RAM, checked from zip and npy headers before anything is inflated."""

from __future__ import annotations

import io
import zipfile

import numpy as np
import pytest

import edge.model.bundle as B
from edge.model.container import parse_npz
from edge.service.config import Config
from tests.support.bundles import make_arrays, write_raw_bundle

RAM_LIMITS = B.limits_for_ram(Config().limits.ram_bytes)


class Inflated:
    """Counts bytes handed out by zip members (what decompression produced)."""

    def __init__(self, monkeypatch):
        self.n = 0
        real = zipfile.ZipExtFile.read

        def read(f, n=-1):
            out = real(f, n)
            self.n += len(out)
            return out

        monkeypatch.setattr(zipfile.ZipExtFile, "read", read)


def _npy_header(shape, dtype="<f8") -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": dtype, "fortran_order": False, "shape": shape})
    return buf.getvalue()


def _bomb(n_bytes: int, declared_shape=None) -> bytes:
    """An npz whose one member inflates to ``n_bytes`` of zeros (its header may claim another shape)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        with zf.open("x_mean.npy", "w", force_zip64=True) as f:
            f.write(_npy_header(declared_shape or (n_bytes // 8,)))
            zeros = bytes(1 << 20)
            for _ in range(n_bytes >> 20):
                f.write(zeros)
    return buf.getvalue()


def test_limits_follow_the_ram_and_never_loosen_the_defaults():
    small, big = B.limits_for_ram(256 * 2**20), B.limits_for_ram(64 * 2**30)
    assert small.max_total_array_bytes == 8 * 2**20 and small.max_array_bytes == 4 * 2**20
    assert big == B.Limits(max_npz_bytes=B.DEFAULT_LIMITS.max_npz_bytes)
    assert RAM_LIMITS.max_total_array_bytes == 16 * 2**20  # the default 512 MiB device
    with pytest.raises(ValueError):
        B.limits_for_ram(0)


def test_zip_bomb_is_refused_from_its_declared_size_without_inflating(monkeypatch):
    # 64 MiB of zeros in well under 1 MiB: twice even the generic per-array bound and eight times the
    # device's, so the declared size alone must refuse it (a bigger bomb only costs compressing time here).
    data = _bomb(64 << 20)
    assert len(data) < 1 << 20 and (64 << 20) >= 2 * B.DEFAULT_LIMITS.max_array_bytes
    inflated = Inflated(monkeypatch)
    with pytest.raises(B.SizeLimitError, match="x_mean"):
        parse_npz(data, "arrays.npz", RAM_LIMITS)
    assert inflated.n == 0


def test_a_header_claiming_a_huge_array_is_refused_having_inflated_only_the_header(monkeypatch):
    # Small member, but its npy header claims 10^9 doubles (a lying header must not size an allocation).
    data = _bomb(1 << 20, declared_shape=(10 ** 9,))
    inflated = Inflated(monkeypatch)
    with pytest.raises(B.SizeLimitError, match="x_mean"):
        parse_npz(data, "arrays.npz", RAM_LIMITS)
    assert inflated.n < 1024


@pytest.fixture(scope="module")
def heavy_bundle(tmp_path_factory):
    """``(path, total array bytes)`` of one heavy bundle, built once: compressing it takes longer than the tests.

    Read-only: the tests parse, load and pack it, never change it.
    """
    return _heavy_bundle(tmp_path_factory.mktemp("heavy"))


def _heavy_bundle(tmp_path):
    """Schema-valid arrays of ~56 MB (a 1900x1900 hidden layer and many golden vectors), all zeros."""
    arrays = {k: np.zeros_like(v) if v.dtype.kind == "f" else v
              for k, v in make_arrays(seed=1, hidden=(1900, 1900)).items()}
    golden = {"mlp_inputs": np.zeros((1_150_000, 2)), "mlp_outputs": np.zeros((1_150_000, 1))}
    a, g = io.BytesIO(), io.BytesIO()
    np.savez_compressed(a, **arrays)
    np.savez_compressed(g, **golden)
    total = sum(v.nbytes for v in arrays.values()) + sum(v.nbytes for v in golden.values())
    path = write_raw_bundle(tmp_path / "heavy", a.getvalue(), g.getvalue())
    return path, total


@pytest.mark.slow  # building and compressing the 56 MB bundle: 0.5 s; the zip bomb and lying-header refusals stay fast
def test_valid_but_heavy_bundle_is_refused_before_inflating(heavy_bundle, monkeypatch):
    path, total = heavy_bundle
    assert total > 56e6 and (path / "arrays.npz").stat().st_size < 1e6
    # Under the generic bounds every array passes the size stage; the device's RAM says no.
    assert total < B.DEFAULT_LIMITS.max_total_array_bytes
    parse_npz((path / "arrays.npz").read_bytes(), "arrays.npz", B.DEFAULT_LIMITS)
    inflated = Inflated(monkeypatch)
    with pytest.raises(B.SizeLimitError):
        B.load_bundle(path, None, limits=RAM_LIMITS)
    assert inflated.n < 64 * 1024


@pytest.mark.slow  # the heavy bundle and a daemon run
def test_heavy_upload_is_refused_and_the_old_model_keeps_serving(tmp_path, heavy_bundle):
    import hashlib

    from host.client import DeviceError
    from edge.protocol.errors import ErrorCode
    from tests.edge.service.test_daemon import running

    path, _ = heavy_bundle
    blob = B.pack_entries([(n.encode(), (path / n).read_bytes()) for n in B.BUNDLE_FILES])
    assert len(blob) < 2e6
    with running(tmp_path / "state") as (c, d, rig, nm):
        before = c.info()["model_sha256"]
        with pytest.raises(DeviceError) as ei:
            c.upload_model(blob)
        assert ei.value.code == ErrorCode.MODEL_REJECTED and "limit" in ei.value.message
        assert c.info()["model_sha256"] == before and hashlib.sha256(blob).hexdigest() != before
        assert c.measure(contact_time_s=0.5)["status"] == "ok"
