"""Scene files: the shipped scenes, reading a file by path or name, and writing variants."""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any, Mapping

from edge.hw.chips import BOARDS, CHIPS
from firmware_sim.scene.model import Scene, SceneError
from firmware_sim.scene.parser import MaterialLookup, parse_scene

__all__ = [
    "SHIPPED_DIR",
    "PRECISION_BOARD",
    "scene_names",
    "scene_path",
    "read_scene",
    "dump_scene_toml",
    "scene_variant",
]

#: The scenes shipped with the package (package data).
SHIPPED_DIR = Path(__file__).with_name("shipped")


def scene_names() -> list[str]:
    """Names of the scenes shipped with the package, sorted."""
    return sorted(p.stem for p in SHIPPED_DIR.glob("*.toml"))


def scene_path(path_or_name: str | Path) -> Path:
    """A scene file: an existing path, or the name of a shipped scene (``"glass_15V"``)."""
    p = Path(path_or_name)
    if p.is_file():
        return p
    if isinstance(path_or_name, str) and "/" not in path_or_name and "\\" not in path_or_name:
        shipped = SHIPPED_DIR / (path_or_name if path_or_name.endswith(".toml") else f"{path_or_name}.toml")
        if shipped.is_file():
            return shipped
        raise FileNotFoundError(
            f"no scene file {path_or_name!r} and no shipped scene of that name "
            f"(shipped: {', '.join(scene_names())})")
    raise FileNotFoundError(f"scene file not found: {p}")


def read_scene(path_or_name: str | Path, *, material_lookup: MaterialLookup | None = None) -> Scene:
    """Read and validate a scene file or shipped scene name (see :func:`parse_scene`)."""
    p = scene_path(path_or_name)
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        raise SceneError(p.name, "", f"not UTF-8 text: {e}") from None
    return parse_scene(text, source=p.name, name=p.stem, material_lookup=material_lookup)


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(f"cannot write a value of type {type(v).__name__} to a scene")


def dump_scene_toml(data: Mapping[str, Any]) -> str:
    """TOML text for a scene mapping (scalars, tables of scalars, arrays of tables)."""
    head = [f"{k} = {_toml_value(v)}" for k, v in data.items() if not isinstance(v, (dict, list))]
    body = []
    for k, v in data.items():
        if isinstance(v, dict):
            body.append(f"\n[{k}]")
            body += [f"{kk} = {_toml_value(vv)}" for kk, vv in v.items()]
        elif isinstance(v, list):
            for item in v:
                body.append(f"\n[[{k}]]")
                body += [f"{kk} = {_toml_value(vv)}" for kk, vv in item.items()]
    return "\n".join(head + body) + "\n"


def scene_variant(path_or_name: str | Path, dest_dir: str | Path, *, suffix: str,
                  **tables: Mapping[str, Any]) -> Path:
    """Write a copy of a scene with whole tables replaced (e.g. ``board={...}``); return its path.

    The copy is validated like any scene; its name gets ``suffix``.
    """
    src = scene_path(path_or_name)
    data = tomllib.loads(src.read_text())
    data["name"] = f"{data.get('name', src.stem)}{suffix}"
    for key, table in tables.items():
        data[key] = dict(table)
    dest = Path(dest_dir) / f"{src.stem}{suffix}.toml"
    dest.parent.mkdir(parents=True, exist_ok=True)
    text = dump_scene_toml(data)
    parse_scene(text, source=str(dest))
    dest.write_text(text)
    return dest


#: The precision board (:data:`edge.hw.chips.BOARDS`): thermocouple EMF and flux on the 24-bit
#: ADS122C04, at its default address, as a scene's ``[board]`` table.
PRECISION_BOARD = {**{name: CHIPS[name].default_address for name in dict.fromkeys(BOARDS["precision"].values())},
                   "stack": "0.42"}
