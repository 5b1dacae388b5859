"""The update policy against replays of every update kind (ISSUE #35 §1-2): model, calibration, object set.

On a probe that takes only signed updates, each kind is installed old-then-new, and the old one --
legitimately signed by the trusted key -- is sent again: refused in one line, what is in use stays, and
re-sending what is in use is accepted (no version change).
"""

from __future__ import annotations

import hashlib

import pytest

from edge.estimation.estimate import mlp_golden_check
from edge.model import bundle as B
from edge.protocol.errors import ErrorCode
from edge.security.keys import signature_document
from host.calibration import install_calibration
from host.client import DeviceError
from host.objects import list_object_sets, upload_object_set
from tests.support.bundles import make_arrays, make_golden, manifest_extra
from tests.support.calibrations import sample_calibration
from tests.support.daemons import strict_probe

pytestmark = pytest.mark.hil


def _bundle(d, tag, seed, created_utc):
    arrays = make_arrays(seed=seed, hidden=(6, 3))
    extra = {**manifest_extra(tag), "created_utc": created_utc}
    return B.write_bundle(d / tag, arrays, make_golden(arrays), extra, golden_check=mlp_golden_check)


def test_an_older_signed_update_of_every_kind_is_refused_after_a_newer_one(tmp_path):
    bundles = {tag: _bundle(tmp_path, tag, seed, t) for tag, seed, t in (
        ("factory", 1, "2024-01-01T00:00:00Z"), ("old", 2, "2025-01-01T00:00:00Z"), ("new", 3, "2025-06-01T00:00:00Z"))}
    with strict_probe(tmp_path, "release", paths={"factory_model": str(bundles["factory"].path)}) as (c, key):
        me = c.info()["device_id"]

        def model(tag):
            manifest = (bundles[tag].path / B.MANIFEST_FILE).read_bytes()
            c.upload_model(B.bundle_to_bytes(bundles[tag].path, signature=signature_document(key, manifest)))

        cals = {"old": sample_calibration(device_id=me, created_utc="2026-11-23T00:00:00Z"),
                "new": sample_calibration(device_id=me, flux_scale=0.95, created_utc="2026-11-24T00:00:00Z")}
        sets = {"old": b"# created_utc: 2026-01-01T00:00:00Z\nname,class,e_W_s05_m2K\ncup,ceramic,1400\n",
                "new": b"# created_utc: 2026-02-01T00:00:00Z\nname,class,e_W_s05_m2K\ncup,ceramic,1450\n"}
        kinds = {
            "model": (model, lambda: c.info()["model_sha256"], {t: b.sha256 for t, b in bundles.items()},
                      "downgrade refused: update 'old' created 2025-01-01T00:00:00Z is not newer than the active"),
            "calibration": (lambda tag: install_calibration(c, cals[tag], key=key),
                            lambda: c.info()["calibration_sha256"], {t: x.sha256 for t, x in cals.items()},
                            "calibration refused: created 2026-11-23T00:00:00Z, not newer than the installed one"),
            "objects": (lambda tag: upload_object_set(c, "kitchen", sets[tag], key=key),
                        lambda: list_object_sets(c)["sets"][0]["sha256"],
                        {t: hashlib.sha256(b).hexdigest() for t, b in sets.items()},
                        "object set 'kitchen' refused: created 2026-01-01T00:00:00Z, not newer than the installed"),
        }
        for kind, (send, in_use, sha, needle) in kinds.items():
            send("old")
            send("new")
            assert in_use() == sha["new"], kind
            with pytest.raises(DeviceError) as ei:
                send("old")   # the replay: signed by the trusted key, but older than what is in use
            assert ei.value.code == ErrorCode.MODEL_REJECTED and needle in str(ei.value), (kind, str(ei.value))
            assert "\n" not in str(ei.value)
            assert in_use() == sha["new"], kind
            send("new")       # what is in use, again: no version change, accepted
            assert in_use() == sha["new"], kind
