"""``thermotouch``: the user's command line (entry point :func:`host.cli.main.main`).

One module per verb (``add_parser(sub)`` and ``run(args)``), argument types in
:mod:`host.cli.args`, the single error path in :mod:`host.cli.main`, output
formatting in :mod:`host.cli.report`.
"""
