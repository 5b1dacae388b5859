"""Keys of what an estimate depends on, by content: for memos that keep whole answers by their exact inputs.

A calibration is its content's SHA-256 (:attr:`edge.calibration.model.ProbeCalibration.sha256`, recomputed from
the content), a library its tables and widths, a module's tunables their current values (a test may change
one).  Computing the first two costs ~0.1-0.2 ms, so they are kept per object, by id with the object itself
held (its id cannot be reused while kept).  NumPy only (edge runtime); imports nothing of the estimators.
"""

from __future__ import annotations

from types import ModuleType
from typing import Any, Callable

__all__ = ["object_key", "calibration_content", "library_key", "tunables"]

#: Content keys of the objects last seen, by id (the object kept with its key).
_OBJECT_KEYS: dict[int, tuple[Any, tuple | None]] = {}
_OBJECT_KEYS_MAX = 16
#: Names of each module's tunables (found once; their values are read at each call).
_TUNABLE_NAMES: dict[str, tuple[str, ...]] = {}


def object_key(obj: Any, make: Callable[[Any], tuple | None]) -> tuple | None:
    """``make(obj)``, kept for the object ``obj`` (a frozen object: its content does not change)."""
    hit = _OBJECT_KEYS.get(id(obj))
    if hit is not None and hit[0] is obj:
        return hit[1]
    key = make(obj)
    if len(_OBJECT_KEYS) >= _OBJECT_KEYS_MAX:
        _OBJECT_KEYS.clear()
    _OBJECT_KEYS[id(obj)] = (obj, key)
    return key


def calibration_content(cal: Any) -> tuple | None:
    """A calibration whose class computes ``sha256`` from its content (a property): that; else None (no key)."""
    if isinstance(getattr(type(cal), "sha256", None), property):
        return ("sha256", type(cal).__module__, type(cal).__qualname__, cal.sha256)
    return None


def _library_content(lib: Any) -> tuple | None:
    from edge.estimation.identification import Library  # noqa: PLC0415

    if type(lib) is not Library:
        return None
    return ("library", lib.effusivity.tobytes(), lib.k.tobytes(), lib.rho_c.tobytes(), lib._ln_e.tobytes(),
            lib._ln_rc.tobytes(), tuple(lib.names), tuple(lib.classes), lib.kernel_floor_ln, lib.rho_c_intrinsic_ln,
            lib.material_spread_ln)


def library_key(library: Any) -> tuple | None:
    """The prior's library as a key: its tables and widths (``("csv",)`` for None; None: not a Library)."""
    return ("csv",) if library is None else object_key(library, _library_content)


def tunables(*modules: ModuleType) -> tuple:
    """The modules' constants (names starting upper-case, numbers and tuples) as they are now."""
    out = []
    for mod in modules:
        names = _TUNABLE_NAMES.get(mod.__name__)
        if names is None:
            names = _TUNABLE_NAMES[mod.__name__] = tuple(
                name for name, v in vars(mod).items() if name[:1].isupper() and isinstance(v, (int, float, tuple)))
        out.extend(getattr(mod, name) for name in names)
    return tuple(out)
