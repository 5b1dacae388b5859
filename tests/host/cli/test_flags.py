"""``thermotouch flags``: every ``edge.status.Flag`` word explained, from the enum's own ``#:`` comments."""

from __future__ import annotations

import inspect
import json

import pytest

import edge.status
from edge.status import Flag
from host.flag_docs import describe_flag, flag_docs
from tests.support.cli import run


def test_every_flag_member_has_an_explanation_in_enum_order():
    docs = flag_docs()
    assert [d.word for d in docs] == [f.value for f in Flag]
    empty = [d.member for d in docs if len(d.text) < 20]
    assert not empty, f"Flag members without a #: comment in edge/status.py: {empty}"
    assert all(d.group.startswith("from ") for d in docs)


def test_the_explanation_is_the_comment_above_the_member():
    lines = inspect.getsource(edge.status).splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith("class Flag("))
    for d in flag_docs():
        at = next(i for i, ln in enumerate(lines) if i > start and ln.strip().startswith(f"{d.member} = "))
        above = []
        while lines[at - 1].strip().startswith("#:"):
            at -= 1
            above.insert(0, lines[at].strip()[2:].strip())
        assert d.text == " ".join(above), d.member


def test_flags_lists_every_word_grouped_with_its_meaning(capsys):
    code, out, err = run(capsys, "flags")
    assert code == 0 and not err
    listed = [ln.strip() for ln in out.splitlines() if ln.startswith("  ") and not ln.startswith("      ")]
    assert listed == [f.value for f in Flag]
    flat = " ".join(out.split())  # the text is wrapped
    assert "from the estimator:" in out and "the probe was not touching" in flat
    assert "``" not in out  # reST markup is not shown to the user


def test_flags_explains_the_words_asked_for_and_json(capsys):
    code, out, _ = run(capsys, "flags", "noisy", "no_contact", "--json")
    assert code == 0
    d = json.loads(out)
    assert [x["word"] for x in d] == ["noisy", "no_contact"]
    assert d[0]["text"] == describe_flag("noisy") and "noise_T_K" in d[0]["text"]
    code, out, _ = run(capsys, "flags", "saturated")
    assert code == 0 and out.splitlines()[1].strip() == "saturated" and "ADC clipped" in out


@pytest.mark.parametrize("word", ["bogus", "NOISY"])
def test_an_unknown_word_is_one_line_and_exit_2(capsys, word):
    code, out, err = run(capsys, "flags", "noisy", word)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2 and len(lines) == 1 and lines[0] == f"thermotouch flags: not a flag word: {word} " \
                                                          "(thermotouch flags lists them)"


def test_describe_flag_of_a_word_this_software_does_not_know():
    assert "not a flag" in describe_flag("from_the_future")


def test_the_parser_reads_groups_multi_line_comments_and_a_member_without_one():
    from host.flag_docs import parse_flag_docs

    src = '''
class Reason:
    #: not this one
    A = "a"


class Flag:
    """Flags."""

    # -- from the first stage
    #: First line,
    #: second line.  Do this.
    A = "a"
    B = "b"  # an ordinary comment is not an explanation
    # -- from the second stage
    #: Third.
    C = "c"
'''
    docs = parse_flag_docs(src, {"A": "a", "B": "b", "C": "c"})
    assert [(d.word, d.group, d.text) for d in docs] == [
        ("a", "from the first stage", "First line, second line.  Do this."),
        ("b", "from the first stage", ""),
        ("c", "from the second stage", "Third."),
    ]
