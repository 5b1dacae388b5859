"""The one validation engine (edge.schema), shared by configuration, protocol and scenes."""

import math

import pytest

from edge.schema import MISSING, Field, SchemaError, check_keys, check_table, check_value


@pytest.mark.parametrize("field, value, expected", [
    (Field("int", lo=0), 3, 3),
    (Field("float", lo=0.0, lo_open=True), 2, 2.0),
    (Field("bool"), True, True),
    (Field("str", hi=4), "abcd", "abcd"),
    (Field("int_or_str", lo=0), "/dev/i2c-1", "/dev/i2c-1"),
    (Field("sha256"), "A" * 64, "a" * 64),
    (Field("list_num"), [1, None, 2.5], [1.0, None, 2.5]),
    (Field("config"), {"a.b": [1, 2]}, {"a.b": [1, 2]}),
    (Field("str", nullable=True), None, None),
])
def test_valid_values_are_normalised(field, value, expected):
    assert check_value(field, value, "x") == expected


@pytest.mark.parametrize("field, value, words", [
    (Field("int"), 1.5, "must be an integer"),
    (Field("int"), True, "must be an integer"),
    (Field("float"), "high", "must be a number"),
    (Field("float"), True, "must be a number"),
    (Field("float"), math.inf, "must be a finite number"),
    (Field("float", lo=0.0, lo_open=True), 0.0, "must be > 0"),
    (Field("float", hi=1.0, hi_open=True), 1.0, "must be < 1"),
    (Field("int", hi=10), 11, "must be <= 10"),
    (Field("bool"), 1, "must be a boolean"),
    (Field("str"), "a\x00b", "NUL"),
    (Field("str", hi=2), "abc", "length must be <= 2"),
    (Field("str", choices=("a", "b")), "c", "must be one of a, b"),
    (Field("sha256"), "xyz", "64 hex digits"),
    (Field("list_num"), [1, "2"], "finite number or null"),
    (Field("config"), {"k": {"nested": 1}}, "scalar"),
    (Field("int"), None, "must not be null"),
])
def test_invalid_values_name_the_path_and_the_rule(field, value, words):
    with pytest.raises(SchemaError, match=words) as ei:
        check_value(field, value, "sec.key")
    assert ei.value.path.startswith("sec.key") and str(ei.value).startswith("sec.key")


def test_tables_fill_defaults_demand_required_and_refuse_unknown_keys():
    fields = {"a": Field("int", default=1), "b": Field("float"), "c": Field("str", default=None)}
    assert check_table({"b": 2}, fields, "t") == {"a": 1, "b": 2.0}
    with pytest.raises(SchemaError, match="missing required field") as ei:
        check_table({}, fields, "t")
    assert ei.value.path == "t.b"
    with pytest.raises(SchemaError, match=r"unknown key \(allowed: a, b, c\)") as ei:
        check_table({"b": 1, "z": 0}, fields, "t")
    assert ei.value.path == "t.z"
    with pytest.raises(SchemaError, match="must be a table"):
        check_table([1], fields, "t")
    check_keys({"a": 1}, ("a",))


def test_required_means_no_default_and_unknown_kinds_fail_at_declaration():
    assert Field("int").required and Field("int", default=MISSING).required
    assert not Field("int", default=0).required
    with pytest.raises(ValueError, match="unknown field kind"):
        Field("complex")
