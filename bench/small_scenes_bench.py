"""The small-heater scenes through the unchanged daemon: ``thermotouch measure --sim SCENE --json``.

One touch of each shipped ``*_small`` scene that docs/science.md ("Through the simulator, end to
end") discusses, measured by the CLI exactly as a user runs it (the device daemon on the emulated
chips of the faithful world, the scene's own contact time), beside the scene's true k and α. The
docs quote these answers; the block is written here so that they are never typed and never stale.

Run:  python bench/small_scenes_bench.py [--update-readme]
Writes bench/results/small_scenes.json; ``--update-readme`` writes the ``small-scenes`` block of docs/science.md.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import time

from _common import ROOT, write_block, write_json
from firmware_sim import load_scene
from host.cli.main import main as thermotouch

SCIENCE_MD = ROOT / "docs" / "science.md"
#: The scenes the docs discuss: a glass and a metal whose k and α a 2-s touch determines, and PMMA, whose it does not.
SCENES = ("glass_15V_small", "alu_20V_small", "pmma_15V_small")


def measure(scene: str) -> dict:
    """The answer of ``thermotouch measure --sim SCENE --json`` and the scene's true k and α."""
    out = io.StringIO()
    t0, c0 = time.perf_counter(), time.process_time()
    with contextlib.redirect_stdout(out):
        rc = thermotouch(["measure", "--sim", scene, "--json"])
    wall_s, cpu_s = time.perf_counter() - t0, time.process_time() - c0
    if rc != 0:
        raise SystemExit(f"thermotouch measure --sim {scene} --json exited {rc}")
    answer = json.loads(out.getvalue().strip().splitlines()[-1])
    sim = load_scene(scene)
    try:
        solid = sim.scene.object.solid
    finally:
        sim.close()
    keys = ("k_W_mK", "k_W_mK_u", "alpha_m2_s", "alpha_m2_s_u", "effusivity_W_s05_m2K",
            "effusivity_W_s05_m2K_u", "determined", "flags", "prior_reason", "contact_time_s")
    return {"answer": {k: answer.get(k) for k in keys},
            "true": {"k_W_mK": solid.k_W_mK, "alpha_m2_s": solid.alpha_m2_s},
            "wall_s": wall_s, "cpu_s_this_process": cpu_s}


def run() -> dict:
    return {"command": "thermotouch measure --sim SCENE --json", "scenes": {s: measure(s) for s in SCENES}}


def _pm(value, u, scale: float, digits: int) -> str:
    if value is None:
        return "-"
    return f"{value * scale:.{digits}f} ± {u * scale:.{digits}f}" if u is not None else f"{value * scale:.{digits}f}"


def block(res: dict) -> str:
    lines = ["| scene | contact | k (W/(m K)): answer (true) | u(k) | α (mm²/s): answer (true) | u(α) | determined | flags |",
             "|---|---|---|---|---|---|---|---|"]
    for scene, r in res["scenes"].items():
        a, t = r["answer"], r["true"]
        k_digits = 1 if t["k_W_mK"] > 10 else 3
        a_digits = 1 if t["alpha_m2_s"] > 1e-5 else 3
        u_k = a["k_W_mK_u"] / a["k_W_mK"] if a["k_W_mK"] and a["k_W_mK_u"] is not None else None
        u_a = a["alpha_m2_s_u"] / a["alpha_m2_s"] if a["alpha_m2_s"] and a["alpha_m2_s_u"] is not None else None
        lines.append(
            f"| {scene} | {a['contact_time_s']:g} s | {_pm(a['k_W_mK'], a['k_W_mK_u'], 1, k_digits)} "
            f"({t['k_W_mK']:.{k_digits}f}) | {'-' if u_k is None else f'{100 * u_k:.0f} %'} "
            f"| {_pm(a['alpha_m2_s'], a['alpha_m2_s_u'], 1e6, a_digits)} ({1e6 * t['alpha_m2_s']:.{a_digits}f}) "
            f"| {'-' if u_a is None else f'{100 * u_a:.0f} %'} | {', '.join(a['determined'] or []) or '-'} "
            f"| {', '.join(f'`{f}`' for f in a['flags'] or []) or '-'} |")
    reasons = [f"{s}: {r['answer']['prior_reason']}" for s, r in res["scenes"].items() if r["answer"]["prior_reason"]]
    text = "\n".join(lines) + "\n\nOne touch per scene, ± one standard uncertainty (k = 1)"
    if reasons:
        text += "; `prior_reason`: " + "; ".join(reasons)
    return text + " (`python bench/small_scenes_bench.py --update-readme`, each row `thermotouch measure --sim SCENE --json`)."


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--update-readme", action="store_true", help="write the small-scenes block of docs/science.md")
    args = ap.parse_args(argv)
    res = run()
    write_json("small_scenes", res)
    text = block(res)
    print(text)
    if args.update_readme:
        write_block("small-scenes", text, SCIENCE_MD)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
