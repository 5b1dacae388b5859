"""Tests for the material library (edge/materials.py and edge/physics/data/materials.csv)."""

import math
from importlib import resources

import numpy as np
import pytest

from edge.physics.materials import (
    CLASSES,
    CLASS_TO_GROUP,
    REPORT_GROUPS,
    REQUIRED_COLUMNS,
    Material,
    MaterialLibrary,
    MaterialLibraryError,
    load_materials,
)

HEADER = "name,class,k_W_mK,rho_kg_m3,c_J_kgK,source,note"
GOOD_ROWS = [
    "copper,metal,401,8933,385,Incropera 7e A.1,",
    "pmma_generic,polymer,0.19,1190,1470,handbook,",
    "granite,stone,2.79,2630,775,Incropera 7e A.3,Barre",
]
# Two comment lines and a blank line precede the header, so the header is line 4 and the
# first data row is line 5: line numbers must count physical lines, not data rows.
PREAMBLE = "# test library\n# second comment\n\n"


def write_csv(tmp_path, header=HEADER, rows=GOOD_ROWS, name="lib.csv"):
    p = tmp_path / name
    p.write_text(PREAMBLE + header + "\n" + "\n".join(rows) + "\n", encoding="utf-8")
    return p


# -- the shipped library ------------------------------------------------------------------

def test_shipped_library_loads_with_enough_materials(lib):
    assert isinstance(lib, MaterialLibrary)
    assert len(lib) >= 75  # assignment; the paper used 67
    assert len(lib) == len(set(lib.names))
    assert lib.path == "edge/physics/data/materials.csv"


def test_shipped_library_is_packaged_resource():
    res = resources.files("edge.physics").joinpath("data/materials.csv")
    assert res.is_file()
    assert len(load_materials(str(res))) == len(load_materials())


def test_k_range_covers_paper_fig5(lib):
    assert lib.k.min() <= 0.06
    assert lib.k.max() >= 405.5
    # the spread must not be concentrated at one end: at least 10 materials per decade band
    for lo, hi in [(0.01, 0.1), (0.1, 1.0), (1.0, 10.0), (10.0, 100.0), (100.0, 1000.0)]:
        assert np.count_nonzero((lib.k >= lo) & (lib.k < hi)) >= 5, (lo, hi)


@pytest.mark.parametrize(
    "name,k,rho,c",
    [
        ("paper_material_i", 0.1, 500.2, 2400.0),
        ("paper_material_ii", 1.5, 2659.6, 800.0),
        ("paper_material_iii", 12.0, 7860.0, 477.1),
    ],
)
def test_table1_materials_exact(lib, name, k, rho, c):
    m = lib.get(name)
    assert (m.k_W_mK, m.rho_kg_m3, m.c_J_kgK) == (k, rho, c)
    assert m.cls == "other"


@pytest.mark.parametrize(
    "name,cls,k,rho,c,alpha_mm2_s",
    [
        ("tempered_glass", "glass", 1.097, 2458.4, 809.0, 0.552),
        ("pmma", "polymer", 0.185, 1178.35, 1429.0, 0.110),
        ("aluminium_alloy", "alloy", 120.4, 2651.5, 873.0, 51.9),
    ],
)
def test_table2_samples_exact(lib, name, cls, k, rho, c, alpha_mm2_s):
    m = lib.get(name)
    assert (m.k_W_mK, m.rho_kg_m3, m.c_J_kgK) == (k, rho, c)
    assert m.cls == cls
    # k was derived from the measured alpha, so alpha = k/(rho c) must reproduce Table 2
    assert m.alpha_m2_s * 1e6 == pytest.approx(alpha_mm2_s, rel=5e-3)
    assert "alpha" in m.note and "rho" in m.note


def test_every_report_group_present(lib):
    present = set(lib.classes)
    for cls in ("foam", "wood", "polymer", "glass", "ceramic", "stone", "metal"):
        assert cls in present, cls
    assert set(lib.groups) >= set(REPORT_GROUPS)
    assert set(lib.classes) <= set(CLASSES)


def test_foams_are_realistic_rigid_foams(lib):
    foams = lib.by_class("foam")
    assert len(foams) >= 3
    assert np.all((foams.k >= 0.02) & (foams.k <= 0.06))
    assert np.all(foams.rho <= 200)


def test_every_row_is_sourced_and_named_snake_case(lib):
    import re

    for m in lib:
        assert m.source.strip(), m.name
        assert re.fullmatch(r"[a-z][a-z0-9_]*", m.name), m.name


def test_csv_header_comment_documents_schema():
    text = resources.files("edge.physics").joinpath("data/materials.csv").read_text(encoding="utf-8")
    comments = "\n".join(line for line in text.splitlines() if line.startswith("#"))
    for col in REQUIRED_COLUMNS + ("note",):
        assert col in comments, col
    for cls in CLASSES:
        assert cls in comments, cls


def test_silver_above_paper_max_is_documented(lib):
    if lib.k.max() > 405.5:
        top = lib[int(np.argmax(lib.k))]
        assert "405.5" in top.note


# -- API ----------------------------------------------------------------------------------

def test_derived_properties_of_material():
    m = Material("x", "metal", k_W_mK=200.0, rho_kg_m3=2500.0, c_J_kgK=800.0, source="s")
    assert m.rho_c_J_m3K == pytest.approx(2.0e6)
    assert m.alpha_m2_s == pytest.approx(1.0e-4)
    assert m.effusivity_W_s05_m2K == pytest.approx(math.sqrt(200.0 * 2.0e6))
    assert m.group == "metal"
    assert m.note == ""
    with pytest.raises(AttributeError):
        m.k_W_mK = 1.0  # frozen


def test_arrays_match_materials_and_are_read_only(lib):
    for i, m in enumerate(lib):
        assert lib.k[i] == m.k_W_mK
        assert lib.rho[i] == m.rho_kg_m3
        assert lib.c[i] == m.c_J_kgK
        assert lib.alpha[i] == pytest.approx(m.alpha_m2_s, rel=1e-12)
        assert lib.effusivity[i] == pytest.approx(m.effusivity_W_s05_m2K, rel=1e-12)
        assert lib.rho_c[i] == pytest.approx(m.rho_c_J_m3K, rel=1e-12)
    np.testing.assert_allclose(lib.effusivity, np.sqrt(lib.k * lib.rho * lib.c), rtol=1e-12)
    for arr in (lib.k, lib.rho, lib.c, lib.alpha, lib.effusivity):
        assert arr.shape == (len(lib),)
        with pytest.raises(ValueError):
            arr[0] = 1.0


def test_known_handbook_values(lib):
    copper = lib.get("copper")
    # Incropera tabulates alpha = 117e-6 m^2/s for pure copper at 300 K
    assert copper.alpha_m2_s == pytest.approx(117e-6, rel=0.01)
    assert lib.get("aluminium").alpha_m2_s == pytest.approx(97.1e-6, rel=0.01)


def test_get_unknown_name_suggests_close_matches(lib):
    with pytest.raises(KeyError) as ei:
        lib.get("copperr")
    assert "copper" in str(ei.value)
    with pytest.raises(KeyError):
        lib.get("unobtainium_xyz_qq")
    assert "copper" in lib and "copperr" not in lib
    assert lib[lib.index("copper")].name == "copper"


def test_group_mapping(lib):
    assert lib.group("rubber") == "polymer"
    assert lib.group("alloy") == "metal"
    assert lib.group("other") == "other"
    for cls in REPORT_GROUPS:
        assert lib.group(cls) == cls
    assert lib.group("aluminium_alloy") == "metal"
    assert lib.group("natural_rubber_soft") == "polymer"
    assert lib.group("tempered_glass") == "glass"
    assert set(CLASS_TO_GROUP) == set(CLASSES)
    with pytest.raises(KeyError):
        lib.group("plasma")


def test_by_class_and_by_group(lib):
    metals = lib.by_group("metal")
    assert set(metals.classes) == {"metal", "alloy"}
    assert len(metals) == len(lib.by_class("metal")) + len(lib.by_class("alloy"))
    polymers = lib.by_group("polymer")
    assert "natural_rubber_soft" in polymers and "pmma" in polymers
    with pytest.raises(ValueError, match="cls"):
        lib.by_class("metals")
    with pytest.raises(ValueError, match="group"):
        lib.by_group("alloy")


def test_library_constructor_rejects_duplicates():
    m = Material("a", "metal", 1.0, 1000.0, 500.0, "s")
    with pytest.raises(MaterialLibraryError, match="duplicate"):
        MaterialLibrary([m, m])


# -- loading custom files -----------------------------------------------------------------

def test_custom_file_loads_with_path_and_str(tmp_path):
    p = write_csv(tmp_path)
    for arg in (p, str(p)):
        lib = load_materials(arg)
        assert lib.names == ("copper", "pmma_generic", "granite")
        assert lib.get("granite").note == "Barre"
        assert lib.path == str(p)


def test_note_column_is_optional(tmp_path):
    header = "name,class,k_W_mK,rho_kg_m3,c_J_kgK,source"
    rows = ["copper,metal,401,8933,385,Incropera 7e A.1"]
    lib = load_materials(write_csv(tmp_path, header=header, rows=rows))
    assert lib.get("copper").note == ""


def test_quoted_fields_with_commas(tmp_path):
    rows = ['copper,metal,401,8933,385,"Incropera, 7e A.1","pure, annealed"']
    lib = load_materials(write_csv(tmp_path, rows=rows))
    assert lib.get("copper").source == "Incropera, 7e A.1"


def _error_for(path):
    with pytest.raises(MaterialLibraryError) as ei:
        load_materials(path)
    assert isinstance(ei.value, ValueError)
    return ei.value


# Each case: replacement for the 2nd data row (file line 6), expected column, message fragment.
BAD_ROW_CASES = [
    ("pmma_generic,polymer,abc,1190,1470,handbook,", "k_W_mK", "not a number"),
    ("pmma_generic,polymer,nan,1190,1470,handbook,", "k_W_mK", "not finite"),
    ("pmma_generic,polymer,0.19,inf,1470,handbook,", "rho_kg_m3", "not finite"),
    ("pmma_generic,polymer,0.19,1190,-inf,handbook,", "c_J_kgK", "not finite"),
    ("pmma_generic,polymer,5000,1190,1470,handbook,", "k_W_mK", "outside"),
    ("pmma_generic,polymer,0.001,1190,1470,handbook,", "k_W_mK", "outside"),
    ("pmma_generic,polymer,0.19,1.19,1470,handbook,", "rho_kg_m3", "outside"),  # g/cm^3 slip
    ("pmma_generic,polymer,0.19,1190,1.47,handbook,", "c_J_kgK", "outside"),  # J/g/K slip
    ("pmma_generic,polymer,0.19,20000,4000,handbook,", "rho_kg_m3*c_J_kgK", "volumetric"),
    ("pmma_generic,polymer,0.19,6,1000,handbook,", "rho_kg_m3*c_J_kgK", "volumetric"),
    ("pmma_generic,plastic,0.19,1190,1470,handbook,", "class", "unknown class"),
    ("pmma_generic,,0.19,1190,1470,handbook,", "class", "empty"),
    (",polymer,0.19,1190,1470,handbook,", "name", "empty"),
    ("pmma_generic,polymer,,1190,1470,handbook,", "k_W_mK", "empty"),
    ("pmma_generic,polymer,0.19,1190,1470,,", "source", "empty"),
    ("PMMA Generic,polymer,0.19,1190,1470,handbook,", "name", "lower_snake_case"),
    ("pmma_generic,polymer,0.19,1190,1470", "source", "missing"),
    ("pmma_generic,polymer,0.19,1190,1470,handbook,,extra", "extra field", "fields"),
]


@pytest.mark.parametrize("row,column,fragment", BAD_ROW_CASES)
def test_bad_row_names_file_line_and_column(tmp_path, row, column, fragment):
    rows = [GOOD_ROWS[0], row, GOOD_ROWS[2]]
    p = write_csv(tmp_path, rows=rows)
    err = _error_for(p)
    assert len(err.issues) == 1, err.issues
    issue = err.issues[0]
    assert issue.line == 6
    assert column in issue.column
    msg = str(err)
    assert str(p) in msg
    assert "line 6" in msg
    assert column in msg
    assert fragment in msg


def test_duplicate_names_name_both_lines(tmp_path):
    rows = [GOOD_ROWS[0], GOOD_ROWS[1], GOOD_ROWS[2], "copper,metal,390,8900,385,other,"]
    err = _error_for(write_csv(tmp_path, rows=rows))
    assert len(err.issues) == 1
    issue = err.issues[0]
    assert (issue.line, issue.column) == (8, "name")
    assert "lines 5 and 8" in str(err)


@pytest.mark.parametrize(
    "header,column",
    [
        ("name,class,k_W_mK,rho_kg_m3,source,note", "c_J_kgK"),
        ("name,k_W_mK,rho_kg_m3,c_J_kgK,source,note", "class"),
        ("name,class,k_W_mK,rho_kg_m3,c_J_kgK,source,note,colour", "colour"),
        ("name,class,k_W_mK,k_W_mK,rho_kg_m3,c_J_kgK,source", "k_W_mK"),
    ],
)
def test_bad_header_names_header_line_and_column(tmp_path, header, column):
    p = write_csv(tmp_path, header=header)
    err = _error_for(p)
    assert any(i.line == 4 and i.column == column for i in err.issues), err.issues
    assert f"line 4, column '{column}'" in str(err)
    # a broken header stops parsing, so rows are not misreported against it
    assert all(i.line == 4 for i in err.issues)


def test_all_problems_reported_at_once(tmp_path):
    rows = [
        "copper,metal,abc,8933,385,Incropera 7e A.1,",
        GOOD_ROWS[1],
        "granite,rock,2.79,2630,775,Incropera 7e A.3,",
    ]
    err = _error_for(write_csv(tmp_path, rows=rows))
    where = {(i.line, i.column) for i in err.issues}
    assert where == {(5, "k_W_mK"), (7, "class")}


@pytest.mark.parametrize("content", ["", "# only a comment\n\n", HEADER + "\n"])
def test_empty_or_header_only_file_is_an_error(tmp_path, content):
    p = tmp_path / "empty.csv"
    p.write_text(content, encoding="utf-8")
    err = _error_for(p)
    assert str(p) in str(err)


def test_missing_file_raises_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError):
        load_materials(tmp_path / "nope.csv")
