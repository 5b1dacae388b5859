"""Declarative schema of a model bundle's arrays (what ``arrays.npz`` and ``golden.npz`` may hold).

The schema is plain data: for each array name an :class:`ArraySpec` (dtype kind, shape with
symbolic dimensions, required flag, size bound, value constraints). Symbolic dimensions such as
``'n_features'`` must resolve to the same integer in every array (and in the golden vectors)
of one bundle. Per-layer arrays whose count is itself stored in the bundle (the MLP's
``mlp_W{i}``/``mlp_b{i}``) are declared once as a :class:`LayerFamily`.

Extending the schema
--------------------
* A new **optional** array (old bundles stay valid): add an entry to ``SCHEMA_V1.arrays``
  below (or ``SCHEMA_V1.golden`` for a golden vector), or call :func:`declare_array` from the
  module that owns it. Prefer editing this file: a bundle is refused if it holds an array whose
  declaring module has not been imported yet.
* A new **required** array or a changed meaning: copy the schema into a new
  ``Schema(version=2, ...)``, register it in :data:`SCHEMAS` and bump
  :data:`CURRENT_SCHEMA_VERSION`; loaders keep accepting version 1 bundles.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Mapping


Dim = int | str
"""A dimension: a fixed size, or the name of a symbolic size shared across arrays."""

KINDS = {"f": "float64", "i": "int64", "U": "unicode"}
NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]{0,63}$")
"""Array names: identifiers of at most 64 characters (they become zip member names)."""


@dataclass(frozen=True)
class ArraySpec:
    """What one named array must look like.

    Parameters
    ----------
    kind : {'f', 'i', 'U'}
        ``'f'`` little-endian float64, ``'i'`` little-endian int64, ``'U'`` unicode string.
    shape : tuple of int or str
        Fixed sizes and/or symbolic dimension names; ``()`` for a scalar. ``ndim`` is its length.
    required : bool
        Whether every bundle of this schema version must hold the array.
    max_elements : int
        Upper bound on the number of elements.
    max_str_len : int
        For ``kind='U'``: maximum characters per string (``'<U64'`` -> 64).
    group : str or None
        Arrays sharing a group name are all-or-none (e.g. the material library tables).
    allowed : tuple of int or None
        For integer codes: the permitted values.
    min_value, max_value : float or None
        Inclusive bounds on every element (numeric kinds only).
    doc : str
        Meaning and units.
    """

    kind: str
    shape: tuple[Dim, ...]
    required: bool = True
    max_elements: int = 1_000_000
    max_str_len: int = 64
    group: str | None = None
    allowed: tuple[int, ...] | None = None
    min_value: float | None = None
    max_value: float | None = None
    doc: str = ""

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"ArraySpec.kind: expected one of {sorted(KINDS)}, got {self.kind!r}")
        if not isinstance(self.shape, tuple) or not all(
            isinstance(d, str) or (isinstance(d, int) and d >= 0) for d in self.shape
        ):
            raise ValueError(f"ArraySpec.shape: expected a tuple of ints >= 0 / str, got {self.shape!r}")
        if self.max_elements < 1:
            raise ValueError("ArraySpec.max_elements: must be >= 1")

    @property
    def ndim(self) -> int:
        return len(self.shape)


@dataclass(frozen=True)
class LayerFamily:
    """A run of per-layer arrays whose count is stored in the bundle.

    Member names and symbolic dims are ``str.format`` templates with ``{i}`` (layer index,
    0-based) and ``{j}`` (= i + 1). After formatting, a dim symbol listed in ``dim_aliases``
    (keys formatted with ``{n}`` = layer count) is replaced by its value, which ties the first
    and last layers to the rest of the pipeline.
    """

    count: str
    max_count: int
    members: Mapping[str, ArraySpec]
    dim_aliases: Mapping[str, Dim] = field(default_factory=dict)

    def expand(self, n: int) -> dict[str, ArraySpec]:
        """Concrete specs for a bundle holding ``n`` layers."""
        aliases = {k.format(n=n): v for k, v in self.dim_aliases.items()}
        out: dict[str, ArraySpec] = {}
        for i in range(n):
            for tname, spec in self.members.items():
                shape = []
                for d in spec.shape:
                    if isinstance(d, str):
                        d = d.format(i=i, j=i + 1)
                        d = aliases.get(d, d)
                    shape.append(d)
                out[tname.format(i=i, j=i + 1)] = ArraySpec(
                    kind=spec.kind,
                    shape=tuple(shape),
                    required=True,
                    max_elements=spec.max_elements,
                    max_str_len=spec.max_str_len,
                    allowed=spec.allowed,
                    min_value=spec.min_value,
                    max_value=spec.max_value,
                    doc=spec.doc,
                )
        return out

    def template_regex(self) -> re.Pattern[str]:
        """Regex matching any member name of any layer (to recognise family members)."""
        alts = [re.escape(t).replace(r"\{i\}", r"\d+").replace(r"\{j\}", r"\d+") for t in self.members]
        return re.compile("^(?:" + "|".join(alts) + ")$")


@dataclass(frozen=True)
class Schema:
    """All arrays a bundle of one ``schema_version`` may hold."""

    version: int
    arrays: dict[str, ArraySpec]
    golden: dict[str, ArraySpec]
    families: tuple[LayerFamily, ...] = ()


ACTIVATION_CODES: dict[str, int] = {"identity": 0, "tanh": 1, "relu": 2, "logistic": 3}
"""Integer codes stored in a bundle for each activation name (scikit-learn's names)."""

ACTIVATION_NAMES: dict[int, str] = {code: name for name, code in ACTIVATION_CODES.items()}

_ACT_CODES = tuple(sorted(ACTIVATION_NAMES))
_TINY = 1e-300  # "strictly positive" without an exclusive-bound flag

SCHEMA_V1 = Schema(
    version=1,
    arrays={
        "feature_version": ArraySpec(
            "i", (), min_value=0, doc="Version of the feature definitions (u_1..u_n) the model expects."
        ),
        "x_log_offset": ArraySpec(
            "f", ("n_features",), doc="Per-feature offset/sign handling applied before ln (see pipeline)."
        ),
        "x_mean": ArraySpec("f", ("n_features",), doc="Normalisation centre of ln-features."),
        "x_scale": ArraySpec(
            "f", ("n_features",), min_value=_TINY, doc="Normalisation scale of ln-features (> 0)."
        ),
        "pca_mean": ArraySpec("f", ("n_features",), doc="PCA centre in normalised-feature space."),
        "pca_components": ArraySpec(
            "f", ("n_components", "n_features"), doc="PCA axes, rows are components (sklearn components_)."
        ),
        "pca_explained_variance_ratio": ArraySpec(
            "f", ("n_components",), min_value=0.0, max_value=1.0, doc="Variance fraction per component."
        ),
        "mlp_n_layers": ArraySpec("i", (), min_value=1, max_value=16, doc="Number of weight layers."),
        "mlp_hidden_activation": ArraySpec(
            "i", (), allowed=_ACT_CODES, doc="Hidden activation code (edge.estimation.mlp.ACTIVATION_CODES)."
        ),
        "mlp_output_activation": ArraySpec(
            "i", (), allowed=_ACT_CODES, doc="Output activation code (identity for regression)."
        ),
        "y_transform": ArraySpec(
            "i", (), allowed=(0, 1), doc="0: prediction = output; 1: prediction = exp(output)."
        ),
        "lib_effusivity": ArraySpec(
            "f", ("n_materials",), required=False, group="lib", min_value=_TINY,
            doc="Library effusivity, W s^0.5 m^-2 K^-1.",
        ),
        "lib_k": ArraySpec(
            "f", ("n_materials",), required=False, group="lib", min_value=_TINY,
            doc="Library thermal conductivity, W m^-1 K^-1.",
        ),
        "lib_rho_c": ArraySpec(
            "f", ("n_materials",), required=False, group="lib", min_value=_TINY,
            doc="Library volumetric heat capacity, J m^-3 K^-1.",
        ),
        "lib_names": ArraySpec(
            "U", ("n_materials",), required=False, group="lib", max_str_len=64, doc="Material names."
        ),
        "lib_class": ArraySpec(
            "U", ("n_materials",), required=False, group="lib", max_str_len=64, doc="Material class labels."
        ),
        "prior_coef": ArraySpec(
            "f", ("n_coef",), required=False,
            doc="Prior-model coefficients (edge.estimation.estimate.PRIOR_COEF_NAMES: kernel width and spreads in ln units).",
        ),
        "pca_score_min": ArraySpec(
            "f", ("n_components",), required=False, group="pca_range",
            doc="Smallest PCA score per component over the training set (range flag).",
        ),
        "pca_score_max": ArraySpec(
            "f", ("n_components",), required=False, group="pca_range",
            doc="Largest PCA score per component over the training set (range flag).",
        ),
    },
    golden={
        "mlp_inputs": ArraySpec(
            "f", ("n_golden", "n_components"), max_elements=100_000, doc="MLP inputs (PCA scores)."
        ),
        "mlp_outputs": ArraySpec(
            "f", ("n_golden",), max_elements=100_000, doc="Expected raw MLP outputs (before y_transform)."
        ),
        "pipeline_features": ArraySpec(
            "f", ("n_golden_pipeline", "n_features"), required=False, group="pipeline_golden",
            max_elements=100_000, doc="Raw features u1..u8 fed to the whole paper pipeline.",
        ),
        "pipeline_k": ArraySpec(
            "f", ("n_golden_pipeline",), required=False, group="pipeline_golden", max_elements=100_000,
            doc="Expected k (W/m/K) from the whole paper pipeline for pipeline_features.",
        ),
    },
    families=(
        LayerFamily(
            count="mlp_n_layers",
            max_count=16,
            members={
                "mlp_W{i}": ArraySpec("f", ("mlp_d{i}", "mlp_d{j}"), doc="Layer weights (n_in, n_out)."),
                "mlp_b{i}": ArraySpec("f", ("mlp_d{j}",), doc="Layer biases (n_out,)."),
            },
            # First layer eats the PCA scores; the network has a single output.
            dim_aliases={"mlp_d0": "n_components", "mlp_d{n}": 1},
        ),
    ),
)

SCHEMAS: dict[int, Schema] = {1: SCHEMA_V1}
"""Known schema versions; a bundle naming any other version is refused."""

CURRENT_SCHEMA_VERSION = 1
"""Version written by :func:`edge.model.bundle.write_bundle` unless told otherwise."""


def declare_array(
    name: str, spec: ArraySpec, *, golden: bool = False, version: int = CURRENT_SCHEMA_VERSION
) -> None:
    """Add an array to a schema version at run time.

    Re-declaring the same name with an identical spec is a no-op; a conflicting spec raises.
    New entries in an existing version should be optional (``required=False``), otherwise
    bundles written before the declaration stop loading.

    Raises
    ------
    ValueError
        Bad name, unknown version, or a conflicting earlier declaration.
    """
    if not NAME_RE.match(name):
        raise ValueError(f"name: {name!r} is not an identifier of at most 64 characters")
    if version not in SCHEMAS:
        raise ValueError(f"version: unknown schema version {version}")
    schema = SCHEMAS[version]
    table = schema.golden if golden else schema.arrays
    other = schema.arrays if golden else schema.golden
    if name in other:
        raise ValueError(f"name: {name!r} is already declared in the other table of schema v{version}")
    if name in table:
        if table[name] != spec:
            raise ValueError(f"name: {name!r} already declared in schema v{version} with {table[name]}")
        return
    table[name] = spec


def describe(version: int = CURRENT_SCHEMA_VERSION) -> Mapping[str, ArraySpec]:
    """Read-only view of a version's non-family arrays (for documentation/CLI listing)."""
    return MappingProxyType(SCHEMAS[version].arrays)
