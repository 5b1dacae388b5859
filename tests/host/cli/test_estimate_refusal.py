"""Every ``estimate --json`` answer carries the recognition keys, a refused touch too (ISSUE #37)."""

import json

import edge.estimation.seam as seam
from edge.estimation.result import RESULT_KEYS
from host.cli.main import main


def test_a_refused_touch_still_answers_every_key_with_object_unknown(capsys, glass_record, monkeypatch):
    def refuse(record, context, decision=None):
        raise seam.TooFewSamples("heating too short to resample")

    monkeypatch.setattr(seam, "estimate_touch", refuse)
    code = main(["estimate", "--csv", str(glass_record), "--json"])
    out, err = capsys.readouterr()
    assert code != 0 and "heating too short" in err
    d = json.loads(out)
    assert set(RESULT_KEYS) <= set(d)
    assert d["object"] == "unknown" and d["object_posterior"] is None and d["candidates"] == []
    assert d["class"] is None and d["effusivity_W_s05_m2K"] is None and "too short" in d["error"]
    assert d["object_set"] == "library"


def test_an_answer_without_an_estimate_names_no_object_but_has_the_keys(capsys, glass_record, monkeypatch):
    real = seam.estimate_touch

    def no_e(record, context, decision=None):
        from dataclasses import replace
        ctx = replace(context, method=lambda t, dT, q, P, m: {"method": "default", "effusivity_W_s05_m2K": None,
                                                               "flags": ["no_fit"]})
        return real(record, ctx, decision=decision)

    monkeypatch.setattr(seam, "estimate_touch", no_e)
    code = main(["estimate", "--csv", str(glass_record), "--json"])
    out, _ = capsys.readouterr()
    d = json.loads(out)
    assert code != 0 and set(RESULT_KEYS) <= set(d)
    assert d["object"] == "unknown" and d["candidates"] == [] and "no_fit" in d["flags"]
