"""Object sets at the sizes a host can send (ISSUE #35 §7, §11): named problems, never an internal error."""

import pytest

from edge.recognition import ObjectSet
from edge.recognition.objects import ObjectSetError

HEADER = "name,class,k_W_mK,rho_kg_m3,c_J_kgK\n"


def test_a_field_over_the_csv_limit_is_a_named_problem():
    text = HEADER + "glass,glass,1.0,2500,800\n" + "x" * 200_000 + ",glass,1.0,2500,800\n"
    with pytest.raises(ObjectSetError) as ei:
        ObjectSet.from_csv_text(text, "big.csv")
    (issue,) = ei.value.issues
    assert issue.line == 3 and "not a CSV row" in str(ei.value) and "field larger than field limit" in str(ei.value)


def test_every_duplicate_of_a_large_set_is_named_once():
    rows = [f"obj{i},glass,1.0,2500,800" for i in range(15_000)] + ["obj7,glass,1.0,2500,800",
                                                                     "obj11,glass,1.0,2500,800"]
    with pytest.raises(ObjectSetError) as ei:
        ObjectSet.from_csv_text(HEADER + "\n".join(rows) + "\n", "big.csv")
    assert [i.line for i in ei.value.issues] == [15_002, 15_003]
    assert "duplicate name 'obj7'" in str(ei.value)
    s = ObjectSet.from_csv_text(HEADER + "\n".join(rows[:15_000]) + "\n", "big.csv")
    assert len(s) == 15_000
    with pytest.raises(ValueError, match="duplicate object names: obj3$"):
        ObjectSet([s.objects[3], *s.objects[:5]])
