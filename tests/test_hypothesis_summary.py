"""Hypothesis's terminal summary is skipped only where it would print nothing (tests/support/hypothesis_summary.py)."""

import sys
import types

from tests.support.hypothesis_summary import only_with_news


def _reporter(reports, show_statistics=False):
    config = types.SimpleNamespace(getoption=lambda name: show_statistics)
    return types.SimpleNamespace(config=config, stats={"passed": reports})


def test_the_summary_runs_where_hypothesis_is_loaded_asked_for_or_has_news(monkeypatch):
    calls = []
    wrapped = only_with_news(lambda tr: calls.append(tr) or "ran", ("_failing",), "--show")
    plain = types.SimpleNamespace(outcome="passed")
    with_stats = types.SimpleNamespace(outcome="passed", _stats="- 150 passing examples")
    news = types.SimpleNamespace(outcome="failed", _failing="[...]")
    loaded = sys.modules.get("hypothesis") or types.ModuleType("hypothesis")
    monkeypatch.setitem(sys.modules, "hypothesis", loaded)
    assert wrapped(_reporter([plain])) == "ran"                  # a process with Hypothesis loaded
    monkeypatch.delitem(sys.modules, "hypothesis")               # as in the xdist controller
    assert wrapped(_reporter([plain])) is None and len(calls) == 1
    assert wrapped(_reporter([plain, with_stats])) is None        # statistics print only when asked for
    assert wrapped(_reporter([plain, news])) == "ran"            # a worker's report carries a failing example
    assert wrapped(_reporter([plain], show_statistics=True)) == "ran"
    assert len(calls) == 3


def test_this_suites_controller_would_skip_it(pytestconfig):
    plugin = pytestconfig.pluginmanager.get_plugin("hypothesispytest")
    impls = [i for i in pytestconfig.pluginmanager.hook.pytest_terminal_summary.get_hookimpls() if i.plugin is plugin]
    assert [i.function.__name__ for i in impls] == ["wrapped"]   # tests/conftest.py wrapped it


def test_only_a_failing_example_is_news_as_the_summary_prints_statistics_only_when_asked(pytestconfig):
    """The wrapper looks for failing examples only, since the hook it wraps prints statistics only under the option."""
    import inspect

    plugin = pytestconfig.pluginmanager.get_plugin("hypothesispytest")
    impl, = [i for i in pytestconfig.pluginmanager.hook.pytest_terminal_summary.get_hookimpls() if i.plugin is plugin]
    closure = dict(zip(impl.function.__code__.co_freevars, (c.cell_contents for c in impl.function.__closure__)))
    assert closure["keys"] == (plugin.FAILING_EXAMPLES_KEY,)
    assert "if stats and print_stats:" in inspect.getsource(closure["summary"])   # the Hypothesis version read
