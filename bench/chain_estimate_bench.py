"""Compute per measurement of the sensor-chain estimate from contact (ISSUE #10 §3: <= 10 ms), beside the default method.

Records: FaithfulWorld touches of borosilicate glass (paper probe, R_c 2e-5, object 1 K cold,
contact 1 s before heating), at the device's 10 Hz and the precision board's 20 Hz for a 2-s
heating, and 20 Hz for 10 s; and aluminium alloy for 10 s at 20 Hz, where the lateral loss is
profiled over the object's alpha in every fit window (~15 disk fits each; on glass, two).  The
chain's cost includes contact detection, the fit-window choice and the calibration's part of u;
the default method (:class:`edge.estimation.estimate.Estimator`, shipped bundle) is timed on the
same record from heater-on.  Medians [min-max] over interleaved rounds.

Run:  python bench/chain_estimate_bench.py
Writes bench/results/chain_estimate.json.
"""

from __future__ import annotations

import sys

from _common import ROOT, fmt_ms, interleaved, write_json

sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402


def main() -> None:
    from edge.estimation.chain_estimate import estimate_from_contact
    from edge.estimation.estimate import Estimator, pipeline_golden_check
    from edge.model.bundle import load_bundle
    from edge.physics.materials import load_materials
    from firmware_sim.rigs.contact_record import ContactTouch, record_touch
    from thermotouch_models import DEFAULT_BUNDLE

    est = Estimator.from_bundle(load_bundle(DEFAULT_BUNDLE, golden_check=pipeline_golden_check))
    lib = load_materials()
    out = {}
    for name, heat, dt in (("borofloat_33", 2.0, 0.1), ("borofloat_33", 2.0, 0.05), ("borofloat_33", 10.0, 0.05),
                           ("aluminium_alloy", 10.0, 0.05)):
        r = record_touch(ContactTouch(lib.get(name).solid, 2e-5, -1.0, lead_s=1.0, heat_s=heat), dt_s=dt, seed=1)
        t, T, q = r["t_s"], r["T_C"], r["q_W_m2"]
        on = t >= 0
        base = float(np.mean(T[(t < 0) & (t >= -0.5)]))
        cases = {"sensor_chain": lambda: estimate_from_contact(t, T, q),
                 "default": lambda: est.estimate(t[on] - t[on][0], T[on] - base, q[on])}
        tm = interleaved(cases, repeats=9)
        key = f"{heat:g}s_{1 / dt:g}Hz" + ("" if name == "borofloat_33" else f"_{name}")
        out[key] = {"samples": int(t.size),
                    **{name: {k: v for k, v in x.items() if k != "result"} for name, x in tm.items()}}
        print(f"{key} ({t.size} samples): sensor chain {fmt_ms(tm['sensor_chain'])} ms, "
              f"default {fmt_ms(tm['default'])} ms")
    write_json("chain_estimate", out)


if __name__ == "__main__":
    main()
