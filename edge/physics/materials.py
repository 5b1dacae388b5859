"""Material library: thermophysical properties of real solids for training and identification.

The library ships as package data, ``edge/physics/data/materials.csv``, and is loaded with
:func:`load_materials`. Each row is one solid near 300 K; the forward model is run for every
row at every power level to build the training set, and identification compares a measured
effusivity against the rows.

CSV schema
----------
Lines whose first non-blank character is ``#`` and blank lines are comments. The first other
line is the header; every further line is one material. Fields must not contain line breaks
(quoting with ``"`` is allowed for commas). Encoding is UTF-8.

========== ========================================================================
column     meaning
========== ========================================================================
name       unique identifier, lower_snake_case (``[a-z][a-z0-9_]*``)
class      one of :data:`CLASSES`: foam, wood, polymer, rubber, glass, ceramic,
           stone, alloy, metal, other
k_W_mK     thermal conductivity k [W/(m K)], allowed range 0.005 .. 3000
rho_kg_m3  density rho [kg/m^3], allowed range 5 .. 25000
c_J_kgK    specific heat capacity c [J/(kg K)], allowed range 90 .. 5000
source     short citation of the handbook or datasheet table
note       optional free text (composition, direction, caveats); may be empty
========== ========================================================================

The volumetric heat capacity rho*c must lie in 1e4 .. 6e6 J/(m^3 K). Any violation raises
:class:`MaterialLibraryError` whose message names the file, the 1-based line number in the
file and the column, for every bad line found.

Report groups
-------------
Identification is judged on seven groups (:data:`REPORT_GROUPS`). ``rubber`` reports as
``polymer`` and ``alloy`` as ``metal``; ``other`` (the paper's synthetic Table 1 materials,
silicon, paper, ...) stays ``other`` and is not one of the seven.
"""

from __future__ import annotations

import csv
import difflib
import functools
import math
import re
from dataclasses import dataclass
from importlib import resources
from os import PathLike
from pathlib import Path
from typing import Iterable, Iterator, NamedTuple

import numpy as np

from edge.physics.solids import Solid

__all__ = [
    "CLASSES",
    "RECOGNITION_CLASS",
    "CLASS_TO_GROUP",
    "REPORT_GROUPS",
    "REQUIRED_COLUMNS",
    "OPTIONAL_COLUMNS",
    "K_RANGE_W_MK",
    "RHO_RANGE_kg_m3",
    "C_RANGE_J_KGK",
    "RHO_C_RANGE_J_M3K",
    "Material",
    "MaterialLibrary",
    "MaterialLibraryError",
    "RowIssue",
    "load_materials",
    "default_library_path",
]

CLASSES: tuple[str, ...] = (
    "foam", "wood", "polymer", "rubber", "glass", "ceramic", "stone", "alloy", "metal", "other",
)
REPORT_GROUPS: tuple[str, ...] = ("foam", "wood", "polymer", "glass", "ceramic", "stone", "metal")
CLASS_TO_GROUP: dict[str, str] = {
    "foam": "foam",
    "wood": "wood",
    "polymer": "polymer",
    "rubber": "polymer",
    "glass": "glass",
    "ceramic": "ceramic",
    "stone": "stone",
    "alloy": "metal",
    "metal": "metal",
    "other": "other",
}

#: The class a recognised object is reported in: issue #12's taxonomy, the question a robot asks
#: ("is it metal?", "glass, ceramic or stone?"), coarser than the library's classes (steel is an
#: "alloy" there and copper a "metal"; glass, porcelain and granite differ there and not to a gripper).
RECOGNITION_CLASS: dict[str, str] = {
    "foam": "foam",
    "wood": "wood",
    "polymer": "polymer",
    "rubber": "rubber",
    "glass": "glass/ceramic/stone",
    "ceramic": "glass/ceramic/stone",
    "stone": "glass/ceramic/stone",
    "alloy": "metal",
    "metal": "metal",
    "other": "other",
}

REQUIRED_COLUMNS: tuple[str, ...] = ("name", "class", "k_W_mK", "rho_kg_m3", "c_J_kgK", "source")
OPTIONAL_COLUMNS: tuple[str, ...] = ("note",)

# Physical plausibility bounds. They are wide on purpose: they catch unit slips (g/cm^3 for
# kg/m^3, J/g/K for J/kg/K, mW for W) rather than judge a handbook value.
K_RANGE_W_MK = (0.005, 3000.0)
RHO_RANGE_kg_m3 = (5.0, 25000.0)
C_RANGE_J_KGK = (90.0, 5000.0)
RHO_C_RANGE_J_M3K = (1e4, 6e6)

_NAME_RE = re.compile(r"^[a-z][a-z0-9_]*$")
_NUMERIC = {
    "k_W_mK": K_RANGE_W_MK,
    "rho_kg_m3": RHO_RANGE_kg_m3,
    "c_J_kgK": C_RANGE_J_KGK,
}
_PACKAGE_RESOURCE = ("edge.physics", "data/materials.csv")


class RowIssue(NamedTuple):
    """One problem found while loading a library file.

    Attributes
    ----------
    path : str
        File (or resource label) the problem is in.
    line : int
        1-based line number in the file; 0 when the problem concerns the file as a whole.
    column : str
        Column name, or ``""`` when no single column is at fault.
    message : str
        What is wrong.
    """

    path: str
    line: int
    column: str
    message: str

    def __str__(self) -> str:
        where = f"{self.path}, line {self.line}" if self.line else self.path
        if self.column:
            where += f", column '{self.column}'"
        return f"{where}: {self.message}"


class MaterialLibraryError(ValueError):
    """A material library file is malformed or holds implausible values.

    Parameters
    ----------
    issues : list of RowIssue
        Every problem found; the message lists them all, one per line.

    Attributes
    ----------
    issues : tuple of RowIssue
    """

    def __init__(self, issues: Iterable[RowIssue]):
        self.issues: tuple[RowIssue, ...] = tuple(issues)
        n = len(self.issues)
        head = f"invalid material library ({n} problem{'s' if n != 1 else ''}):"
        super().__init__("\n".join([head] + ["  " + str(i) for i in self.issues]))


@dataclass(frozen=True)
class Material:
    """One solid with its thermophysical properties near 300 K.

    Parameters
    ----------
    name : str
        Unique lower_snake_case identifier.
    cls : str
        Material class, one of :data:`CLASSES` (``class`` in the CSV).
    k_W_mK : float
        Thermal conductivity [W/(m K)].
    rho_kg_m3 : float
        Density [kg/m^3].
    c_J_kgK : float
        Specific heat capacity [J/(kg K)].
    source : str
        Short citation of where the values come from.
    note : str, optional
        Free-text remark.
    """

    name: str
    cls: str
    k_W_mK: float
    rho_kg_m3: float
    c_J_kgK: float
    source: str
    note: str = ""

    @property
    def solid(self) -> Solid:
        """The material's thermal properties as the physics model takes them."""
        return Solid(self.k_W_mK, self.rho_kg_m3, self.c_J_kgK)

    # Derived properties come from edge.physics.solids.Solid: one definition of each.
    rho_c_J_m3K = property(lambda self: self.solid.rho_c_J_m3K, doc="Volumetric heat capacity [J/(m^3 K)].")
    alpha_m2_s = property(lambda self: self.solid.alpha_m2_s, doc="Thermal diffusivity [m^2/s].")
    effusivity_W_s05_m2K = property(
        lambda self: self.solid.effusivity_W_s05_m2K, doc="Thermal effusivity [W s^0.5 / (m^2 K)]."
    )

    @property
    def group(self) -> str:
        """Report group of this material's class (see :data:`CLASS_TO_GROUP`)."""
        return CLASS_TO_GROUP[self.cls]


class MaterialLibrary:
    """An immutable, ordered collection of :class:`Material` with unique names.

    Parameters
    ----------
    materials : iterable of Material
        Kept in the given order; all per-material arrays follow this order.
    path : str, optional
        Where the materials were loaded from (for messages only).

    Raises
    ------
    MaterialLibraryError
        If two materials share a name or a class is unknown.
    """

    def __init__(self, materials: Iterable[Material], path: str = "<memory>"):
        mats = tuple(materials)
        seen: dict[str, int] = {}
        issues = []
        for i, m in enumerate(mats):
            if not isinstance(m, Material):
                raise TypeError(f"materials[{i}] is {type(m).__name__}, expected Material")
            if m.cls not in CLASS_TO_GROUP:
                issues.append(RowIssue(path, 0, "class", f"material {m.name!r} has unknown class {m.cls!r}"))
            if m.name in seen:
                issues.append(RowIssue(path, 0, "name",
                                       f"duplicate name {m.name!r} (items {seen[m.name]} and {i})"))
            seen.setdefault(m.name, i)
        if issues:
            raise MaterialLibraryError(issues)
        self._materials = mats
        self._index = {m.name: i for i, m in enumerate(mats)}
        self.path = path

        def col(values) -> np.ndarray:
            a = np.array(values, dtype=np.float64)
            a.setflags(write=False)
            return a

        self._k = col([m.k_W_mK for m in mats])
        self._rho = col([m.rho_kg_m3 for m in mats])
        self._c = col([m.c_J_kgK for m in mats])
        self._rho_c = col(self._rho * self._c)
        self._alpha = col(self._k / self._rho_c)
        self._eff = col(np.sqrt(self._k * self._rho_c))

    # -- container protocol -------------------------------------------------------------
    def __len__(self) -> int:
        return len(self._materials)

    def __iter__(self) -> Iterator[Material]:
        return iter(self._materials)

    def __contains__(self, name: object) -> bool:
        return name in self._index

    def __getitem__(self, index: int) -> Material:
        """Material at position ``index`` (use :meth:`get` to look up by name)."""
        return self._materials[index]

    def __repr__(self) -> str:
        return f"MaterialLibrary({len(self)} materials from {self.path})"

    # -- lookup -------------------------------------------------------------------------
    def get(self, name: str) -> Material:
        """Material called ``name``.

        Raises
        ------
        KeyError
            If no material has that name; the message suggests close matches.
        """
        try:
            return self._materials[self._index[name]]
        except KeyError:
            close = difflib.get_close_matches(str(name), self._index.keys(), n=5, cutoff=0.5)
            hint = f"; close matches: {', '.join(close)}" if close else ""
            raise KeyError(f"no material named {name!r} in {self.path}{hint}") from None

    def index(self, name: str) -> int:
        """Position of material ``name`` in the library order (KeyError like :meth:`get`)."""
        return self._index[self.get(name).name]

    def group(self, name: str) -> str:
        """Report group for a class name or a material name.

        ``name`` is first taken as a class (``"rubber"`` -> ``"polymer"``, ``"alloy"`` ->
        ``"metal"``); otherwise as a material name, whose class is then mapped.

        Raises
        ------
        KeyError
            If ``name`` is neither a class nor a material in the library.
        """
        if name in CLASS_TO_GROUP:
            return CLASS_TO_GROUP[name]
        return self.get(name).group

    def by_class(self, cls: str) -> "MaterialLibrary":
        """Sub-library of the materials whose class is ``cls`` (ValueError if unknown class)."""
        if cls not in CLASS_TO_GROUP:
            raise ValueError(f"cls must be one of {', '.join(CLASSES)}; got {cls!r}")
        return MaterialLibrary((m for m in self if m.cls == cls), path=self.path)

    def by_group(self, group: str) -> "MaterialLibrary":
        """Sub-library of the materials in report group ``group`` (ValueError if unknown)."""
        valid = set(CLASS_TO_GROUP.values())
        if group not in valid:
            raise ValueError(f"group must be one of {', '.join(sorted(valid))}; got {group!r}")
        return MaterialLibrary((m for m in self if m.group == group), path=self.path)

    # -- per-material views (library order) ---------------------------------------------
    @property
    def names(self) -> tuple[str, ...]:
        """Material names in library order."""
        return tuple(m.name for m in self._materials)

    @property
    def classes(self) -> tuple[str, ...]:
        """Class of each material, in library order."""
        return tuple(m.cls for m in self._materials)

    @property
    def groups(self) -> tuple[str, ...]:
        """Report group of each material, in library order."""
        return tuple(m.group for m in self._materials)

    @property
    def k(self) -> np.ndarray:
        """Thermal conductivity [W/(m K)] per material (read-only array)."""
        return self._k

    @property
    def rho(self) -> np.ndarray:
        """Density [kg/m^3] per material (read-only array)."""
        return self._rho

    @property
    def c(self) -> np.ndarray:
        """Specific heat capacity [J/(kg K)] per material (read-only array)."""
        return self._c

    @property
    def rho_c(self) -> np.ndarray:
        """Volumetric heat capacity [J/(m^3 K)] per material (read-only array)."""
        return self._rho_c

    @property
    def alpha(self) -> np.ndarray:
        """Thermal diffusivity [m^2/s] per material (read-only array)."""
        return self._alpha

    @property
    def effusivity(self) -> np.ndarray:
        """Thermal effusivity sqrt(k rho c) [W s^0.5/(m^2 K)] per material (read-only array)."""
        return self._eff


def default_library_path() -> str:
    """Label of the packaged library resource, ``edge/physics/data/materials.csv``."""
    return "/".join((_PACKAGE_RESOURCE[0].replace(".", "/"), _PACKAGE_RESOURCE[1]))


def load_materials(path: str | PathLike[str] | None = None) -> MaterialLibrary:
    """Load and validate a material library CSV.

    Parameters
    ----------
    path : str or path-like, optional
        CSV file to read. Default: the packaged ``edge/physics/data/materials.csv``.

    Returns
    -------
    MaterialLibrary

    Raises
    ------
    MaterialLibraryError
        If the file breaks the schema in the module docstring; the message names the file,
        the 1-based line and the column of every problem.
    FileNotFoundError
        If ``path`` does not exist.
    """
    if path is None:
        return _packaged_library()
    p = Path(path)
    return MaterialLibrary(_parse(p.read_text(encoding="utf-8-sig"), str(p)), path=str(p))


@functools.cache
def _packaged_library() -> MaterialLibrary:
    """The packaged library, parsed once per process: it is immutable and its file changes only with the package.

    (The test suite loaded it ~630 times in the fast tier, 0.65 CPU-s of parsing.)
    """
    package, rel = _PACKAGE_RESOURCE
    text = resources.files(package).joinpath(rel).read_text(encoding="utf-8-sig")
    label = default_library_path()
    return MaterialLibrary(_parse(text, label), path=label)


def _parse(text: str, label: str) -> list[Material]:
    issues: list[RowIssue] = []

    def bad(line: int, column: str, message: str) -> None:
        issues.append(RowIssue(label, line, column, message))

    header: list[str] | None = None
    header_line = 0
    materials: list[Material] = []
    first_line_of: dict[str, int] = {}

    # Lines are parsed one at a time so every message can cite the physical line number.
    for lineno, raw in enumerate(text.splitlines(), start=1):
        stripped = raw.strip()
        if not stripped or stripped.startswith("#"):
            continue
        fields = [f.strip() for f in next(csv.reader([raw]))]

        if header is None:
            header, header_line = fields, lineno
            allowed = set(REQUIRED_COLUMNS) | set(OPTIONAL_COLUMNS)
            for col in REQUIRED_COLUMNS:
                if col not in header:
                    bad(lineno, col, "required column is missing from the header")
            for col in header:
                if col not in allowed:
                    bad(lineno, col or "<empty>",
                        f"unknown column (allowed: {', '.join(REQUIRED_COLUMNS + OPTIONAL_COLUMNS)})")
            for col in sorted({c for c in header if header.count(c) > 1}):
                bad(lineno, col, "column appears more than once in the header")
            if issues:
                break  # rows cannot be interpreted against a broken header
            continue

        if len(fields) < len(header):
            missing = header[len(fields):]
            bad(lineno, missing[0],
                f"row has {len(fields)} fields but the header (line {header_line}) has {len(header)}; "
                f"missing: {', '.join(missing)}")
            continue
        if len(fields) > len(header):
            bad(lineno, f"<extra field {len(header) + 1}>",
                f"row has {len(fields)} fields but the header (line {header_line}) has {len(header)}")
            continue

        row = dict(zip(header, fields))
        ok = True
        for col in REQUIRED_COLUMNS:
            if row[col] == "":
                bad(lineno, col, "required field is empty")
                ok = False

        name = row["name"]
        if name and not _NAME_RE.match(name):
            bad(lineno, "name", f"{name!r} is not lower_snake_case ([a-z][a-z0-9_]*)")
            ok = False
        cls = row["class"]
        if cls and cls not in CLASS_TO_GROUP:
            bad(lineno, "class", f"unknown class {cls!r} (allowed: {', '.join(CLASSES)})")
            ok = False

        values: dict[str, float] = {}
        for col, (lo, hi) in _NUMERIC.items():
            text_value = row[col]
            if text_value == "":
                continue
            try:
                v = float(text_value)
            except ValueError:
                bad(lineno, col, f"{text_value!r} is not a number")
                ok = False
                continue
            if not math.isfinite(v):
                bad(lineno, col, f"{text_value!r} is not finite")
                ok = False
                continue
            if not lo <= v <= hi:
                bad(lineno, col, f"{v:g} is outside the physical range [{lo:g}, {hi:g}]")
                ok = False
                continue
            values[col] = v

        if len(values) == len(_NUMERIC):
            rho_c = values["rho_kg_m3"] * values["c_J_kgK"]
            lo, hi = RHO_C_RANGE_J_M3K
            if not lo <= rho_c <= hi:
                bad(lineno, "rho_kg_m3*c_J_kgK",
                    f"volumetric heat capacity {rho_c:.4g} J/(m^3 K) is outside [{lo:g}, {hi:g}]")
                ok = False

        if name:
            if name in first_line_of:
                bad(lineno, "name",
                    f"duplicate name {name!r}: lines {first_line_of[name]} and {lineno}")
                ok = False
            else:
                first_line_of[name] = lineno

        if ok:
            materials.append(Material(
                name=name,
                cls=cls,
                k_W_mK=values["k_W_mK"],
                rho_kg_m3=values["rho_kg_m3"],
                c_J_kgK=values["c_J_kgK"],
                source=row["source"],
                note=row.get("note", ""),
            ))

    if header is None:
        bad(0, "", "no header line (file is empty or only comments)")
    elif not issues and not materials:
        bad(0, "", "header present but no material rows")
    if issues:
        raise MaterialLibraryError(issues)
    return materials
