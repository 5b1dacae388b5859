"""The network's tanh units: NumPy's float64 ``tanh`` against ``host.activations.tanh_inplace``.

Times, per element, ``np.tanh(x, out=x)``, ``np.exp(x, out=x)`` (for scale) and
:func:`host.activations.tanh_inplace` on an array the size of one hidden layer's
activations in the shipped recipe's fit (5000 samples x 100 units), interleaved
over ``--repeats`` rounds (median [min-max], less the median time of the copy that
restores the input before each call); and the largest absolute difference
between the two tanh over that array and over +-800. Whether NumPy has a vector
loop for float64 tanh depends on the CPU (AVX-512): the result names it.

Run:  python bench/tanh_bench.py [--repeats 9]
Writes bench/results/tanh.json.
"""

from __future__ import annotations

import argparse

from _common import interleaved, write_json

import numpy as np  # noqa: E402

from host.activations import tanh_inplace  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=9)
    args = ap.parse_args(argv)

    rng = np.random.default_rng(0)
    x0 = rng.normal(0.0, 2.0, (5000, 100))
    buf = np.empty_like(x0)

    def case(fn):
        def run():
            np.copyto(buf, x0)
            fn(buf)
        return run

    copy_only = interleaved({"copy": case(lambda b: None)}, args.repeats)["copy"]["median_s"]
    t = interleaved({"np.tanh": case(lambda b: np.tanh(b, out=b)), "np.exp": case(lambda b: np.exp(b, out=b)),
                     "tanh_inplace": case(tanh_inplace)}, args.repeats)
    per_elem = {name: {k: (v["{}_s".format(k)] - copy_only) / x0.size * 1e9 for k in ("median", "min", "max")}
                for name, v in t.items()}
    y = x0.copy()
    tanh_inplace(y)
    far = np.linspace(-800.0, 800.0, 100_001)
    yf = far.copy()
    tanh_inplace(yf)
    err = {"random_normal_sd2": float(np.max(np.abs(y - np.tanh(x0)))),
           "linspace_pm800": float(np.max(np.abs(yf - np.tanh(far))))}
    for name, v in per_elem.items():
        print(f"{name:>13}: {v['median']:.2f} ns/element [{v['min']:.2f}-{v['max']:.2f}]")
    print(f"largest |tanh_inplace - np.tanh|: {err['random_normal_sd2']:.1e} (N(0, 2)), "
          f"{err['linspace_pm800']:.1e} (+-800)")
    path = write_json("tanh", {"shape": list(x0.shape), "repeats": args.repeats, "ns_per_element": per_elem,
                               "copy_s": copy_only, "max_abs_diff": err})
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
