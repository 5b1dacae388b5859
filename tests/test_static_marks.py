"""Which test modules a ``-m`` expression leaves out uncollected (tests/support/static_marks.py)."""

from pathlib import Path

import pytest

from tests.support.static_marks import excluded_module, excludes, module_marks


@pytest.mark.parametrize("source, marks", [
    ("import pytest\n\npytestmark = pytest.mark.slow\n", {"slow"}),
    ("pytestmark = [pytest.mark.hil, pytest.mark.slow]  # a comment\n", {"hil", "slow"}),
    ('pytestmark = (pytest.mark.slow, pytest.mark.filterwarnings("ignore:x"))\n', {"slow", "filterwarnings"}),
    ("def test_a():\n    pass\n", None),                                        # no module marks
    ("pytestmark = [\n    pytest.mark.slow,\n]\n", None),                       # continued: not read
    ("pytestmark = pytest.mark.slow\nif X:\n    pytestmark = []\n", None),      # reassigned
    ("pytestmark = [pytest.mark.slow] if X else []\n", None),                  # computed
    ("pytestmark = [pytest.mark.slow, MARKS]\n", None),                        # not only marks
    ("    pytestmark = pytest.mark.slow\n", None),                             # not at top level
    ("pytestmark = []\n", None),
])
def test_only_the_plain_pytestmark_line_is_read(source, marks):
    assert module_marks(source) == (None if marks is None else frozenset(marks))


@pytest.mark.parametrize("expr, marks, out", [
    ("not slow", {"slow"}, True),
    ("not slow", {"hil", "slow"}, True),
    ("not slow", {"hil"}, False),
    ("not slow and not hil", {"hil"}, True),
    ("slow", {"slow"}, False),
    ("hil and not slow", {"slow"}, True),
    ("not slow or fast", {"slow"}, False),      # a test of the module may carry `fast`
    ("not (slow and hil)", {"slow"}, False),   # ... or not `hil`
    ("", {"slow"}, False),
    ("not slow", set(), False),
    ("not (", {"slow"}, False),                # malformed: pytest reports it, nothing is left out here
    ("not slow(reason=1)", {"slow"}, False),   # about a mark's arguments: not decided statically
])
def test_a_module_is_left_out_only_if_no_test_of_it_can_match(expr, marks, out):
    assert excludes(expr, frozenset(marks)) is out


def test_a_slow_module_of_this_suite_is_left_out_of_the_fast_tier_and_a_mixed_one_is_not():
    root = Path(__file__).resolve().parent
    assert excluded_module(root / "host" / "test_round_trip.py", "not slow")        # every test slow
    assert not excluded_module(root / "host" / "test_round_trip.py", "slow")
    assert not excluded_module(root / "host" / "test_round_trip.py", "")
    assert not excluded_module(Path(__file__), "not slow")                          # no module marks
