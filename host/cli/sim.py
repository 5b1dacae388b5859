"""``thermotouch sim``: a simulated probe on a virtual serial port until Ctrl-C."""

from __future__ import annotations

import sys


def add_parser(sub, parents):
    p = sub.add_parser("sim", help="run a simulated probe on a virtual serial port until Ctrl-C", parents=parents)
    p.add_argument("scene", help="scene file (.toml) or shipped scene name")
    p.add_argument("--workdir", default=None, help="keep the model store and history here")
    p.set_defaults(func=run)


def run(args) -> int:
    import logging  # noqa: PLC0415

    from firmware_sim.run import run_sim  # noqa: PLC0415
    from host.device import validate_scene  # noqa: PLC0415

    validate_scene(args.scene)  # DeviceUnavailable (exit 2) with the scene's own message
    logging.basicConfig(stream=sys.stderr, level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    return run_sim(args.scene, workdir=args.workdir)
