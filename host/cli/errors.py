"""The CLI's one error type and its exit statuses."""

from __future__ import annotations

__all__ = ["CliError", "EXIT_OK", "EXIT_RUNTIME", "EXIT_BAD_INPUT", "EXIT_REFUSED", "EXIT_INTERRUPTED"]

EXIT_OK = 0
#: A device or runtime failure (no answer, busy, measurement failed, a write failed).
EXIT_RUNTIME = 1
#: Bad arguments or input (checked on the host before any work).
EXIT_BAD_INPUT = 2
#: ``deploy``: the new bundle was refused (nothing flashed).
EXIT_REFUSED = 3
#: Ctrl-C.
EXIT_INTERRUPTED = 130


class CliError(Exception):
    """An error to report to the user as one line on stderr, with an exit status."""

    def __init__(self, message: str, code: int = EXIT_BAD_INPUT, *, prog: str | None = None) -> None:
        super().__init__(message)
        self.code = code
        #: Who says it (``thermotouch measure``); None: the command that runs.
        self.prog = prog
