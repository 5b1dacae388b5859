"""Hypothesis's terminal summary runs only where it has something to say.

Its ``pytest_terminal_summary`` imports ``hypothesis.internal.observability``, and with it all of
Hypothesis (0.3 s of CPU), to read a set of files that only a process running Hypothesis fills. The
xdist controller runs no test: it paid that import at the very end of every run, on the critical
path. :func:`summary_only_with_news` (called by ``tests/conftest.py``) skips the summary when
Hypothesis is not loaded in this process, the statistics were not asked for and no report carries
a failing example (it prints nothing then); otherwise it runs as before. A report's statistics alone
do not make it run: every Hypothesis test's report carries them, and the summary prints them only
when they were asked for (``--hypothesis-show-statistics``), a case it runs for anyway; before, the
controller of every run with a Hypothesis test imported Hypothesis at the end to print nothing.
"""

from __future__ import annotations

import sys
from collections.abc import Callable


def only_with_news(summary: Callable, keys: tuple[str, ...], option: str) -> Callable:
    """``summary(terminalreporter)``, called only if Hypothesis is loaded, ``option`` is set or a report has one of ``keys``."""

    def wrapped(terminalreporter):
        if ("hypothesis" in sys.modules or terminalreporter.config.getoption(option)
                or any(k in r.__dict__ for rs in terminalreporter.stats.values() for r in rs for k in keys)):
            return summary(terminalreporter)
        return None

    return wrapped


def summary_only_with_news(pluginmanager) -> bool:
    """Wrap the Hypothesis plugin's summary hook in :func:`only_with_news`; False (left alone) if it is not the known one.

    The news a report can carry is a failing example (``FAILING_EXAMPLES_KEY``); its statistics
    (``STATS_KEY``) are printed only with the option, which :func:`only_with_news` checks.
    """
    plugin = pluginmanager.get_plugin("hypothesispytest")
    if plugin is None:
        return False
    impls = [i for i in pluginmanager.hook.pytest_terminal_summary.get_hookimpls() if i.plugin is plugin]
    keys = (getattr(plugin, "FAILING_EXAMPLES_KEY", None),)
    option = getattr(plugin, "PRINT_STATISTICS_OPTION", None)
    if len(impls) != 1 or None in keys or option is None or tuple(impls[0].argnames) != ("terminalreporter",):
        return False
    impls[0].function = only_with_news(impls[0].function, keys, option)
    return True
