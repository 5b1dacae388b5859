"""Cost of Ed25519 (cryptography, edge/security/ed25519.py) on the device's update path: import, verify, sign.

What a signed update costs the probe: importing ``edge.security.ed25519``
(and the policy module that uses it) in a fresh interpreter, and one
signature verification over the shipped bundle's manifest (about 1.2 kB,
the message a real update signs). Signing and key derivation (host side) are
reported for completeness. Every case runs ``--rounds`` times interleaved
(case 1..n, then again), each round timing a batch of ``--batch`` calls;
reported per call as the median over rounds with min-max. Import times are
timed inside fresh subprocesses (``python -c``), interleaved the same way;
``hashlib`` (OpenSSL), which the device loads anyway for the bundle hashes,
is reported alone to show how much of the import is its.

Run:  python bench/ed25519_bench.py [--rounds 9] [--batch 20] [--update-readme]
Writes bench/results/ed25519.json (and the table between the ed25519-bench markers in docs/results.md).
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _common import ROOT, write_block, write_json

from edge.security import ed25519  # noqa: E402
from edge.security.keys import SecretKey, signature_document  # noqa: E402
from edge.security.policy import UpdatePolicy  # noqa: E402

_IMPORT_SNIPPET = ("import sys, time; sys.path.insert(0, {root!r}); t0 = time.perf_counter(); import {mod}; "
                   "print(time.perf_counter() - t0)")


def _subprocess_import_s(mod: str) -> float:
    """Wall time of ``import mod`` measured inside a fresh interpreter (s)."""
    out = subprocess.run([sys.executable, "-c", _IMPORT_SNIPPET.format(root=str(ROOT), mod=mod)],
                         capture_output=True, text=True, check=True)
    return float(out.stdout.strip())


def _summary_ms(values_s: list[float]) -> dict:
    ms = [v * 1e3 for v in values_s]
    return {"median_ms": statistics.median(ms), "min_ms": min(ms), "max_ms": max(ms), "n": len(ms)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=9)
    ap.add_argument("--batch", type=int, default=20)
    ap.add_argument("--update-readme", action="store_true", help="rewrite its table in docs/results.md")
    args = ap.parse_args(argv)

    from thermotouch_models import DEFAULT_BUNDLE  # noqa: PLC0415

    manifest = (Path(DEFAULT_BUNDLE) / "manifest.json").read_bytes()
    key = SecretKey.generate("bench")
    sig = key.sign(manifest)
    sig_doc = signature_document(key, manifest)
    keys_dir = Path(tempfile.mkdtemp(prefix="ed25519-bench-"))
    (keys_dir / "bench.public.json").write_text(json.dumps(key.public_key().document()))
    policy = UpdatePolicy(str(keys_dir), allow_unsigned=False)

    cases = {
        "verify": lambda: ed25519.check_signature(key.public, manifest, sig),
        "authenticate (read key dir + parse + verify)": lambda: policy.authenticate(manifest, sig_doc),
        "sign": lambda: ed25519.sign(key.secret, manifest),
        "public_key": lambda: ed25519.public_key(key.secret),
    }
    times: dict[str, list[float]] = {name: [] for name in cases}
    for _ in range(args.rounds):
        for name, fn in cases.items():
            t0 = time.perf_counter()
            for _ in range(args.batch):
                fn()
            times[name].append((time.perf_counter() - t0) / args.batch)

    imports = {"edge.security.ed25519": [], "edge.security.policy": [], "hashlib": []}
    for _ in range(args.rounds):
        for mod in imports:
            imports[mod].append(_subprocess_import_s(mod))

    result = {
        "message_bytes": len(manifest),
        "rounds": args.rounds,
        "batch": args.batch,
        "per_call": {name: _summary_ms(v) for name, v in times.items()},
        "import_in_fresh_interpreter": {mod: _summary_ms(v) for mod, v in imports.items()},
    }
    path = write_json("ed25519", result)
    print(f"message: shipped manifest.json, {len(manifest)} B; {args.rounds} interleaved rounds x {args.batch} calls")
    for name, s in result["per_call"].items():
        print(f"  {name:46} median {s['median_ms']:7.2f} ms  (range {s['min_ms']:.2f}-{s['max_ms']:.2f})")
    print("import in a fresh interpreter (NumPy not loaded):")
    for mod, s in result["import_in_fresh_interpreter"].items():
        print(f"  import {mod:40} median {s['median_ms']:7.2f} ms  (range {s['min_ms']:.2f}-{s['max_ms']:.2f})")
    print(f"wrote {path}")
    if args.update_readme:
        write_block("ed25519-bench", readme_table(result))
        print("docs/results.md table updated")
    return 0


_README_ROWS = (
    ("per_call", "verify", "verify one signature (shipped manifest, {n} B)"),
    ("per_call", "authenticate (read key dir + parse + verify)",
     "authenticate an update (read trusted keys, parse, verify)"),
    ("per_call", "sign", "sign (host)"),
    ("per_call", "public_key", "derive a public key (host)"),
    ("import_in_fresh_interpreter", "edge.security.ed25519", "`import edge.security.ed25519` in a fresh interpreter"),
    ("import_in_fresh_interpreter", "edge.security.policy",
     "`import edge.security.policy` (datetime, logging, json: already loaded in the daemon)"),
    ("import_in_fresh_interpreter", "hashlib", "`import hashlib` alone (OpenSSL; the device loads it anyway)"),
)


def readme_table(result: dict) -> str:
    """The docs/results.md table of the figures in ``result``."""
    lines = ["| step | median | range |", "|---|---|---|"]
    for group, name, label in _README_ROWS:
        s = result[group][name]
        lines.append(f"| {label.format(n=result['message_bytes'])} | {s['median_ms']:.1f} ms | "
                     f"{s['min_ms']:.1f}–{s['max_ms']:.1f} ms |")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
