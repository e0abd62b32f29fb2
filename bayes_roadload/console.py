"""What the command line shows: output lines, log messages, warnings and progress, all through
:mod:`logging`.

* The commands' own output (tables, "wrote ..." lines) is logged at INFO by the
  ``bayes_roadload.cli`` logger and written to standard output; every other
  ``bayes_roadload`` logger (stages, MAP, chains, retries) writes to standard error.
* ``--quiet`` shows warnings and errors only (no progress bars); the default shows INFO;
  ``--verbose`` adds DEBUG (stage details, and the third-party warnings).
* Warnings raised by this package are shown as warnings; warnings of third-party libraries
  (ArviZ, numpyro, JAX, ...), which the user cannot act on, are logged at DEBUG.
* Progress bars are drawn only on a terminal; elsewhere (a log file, a pipe, a batch worker)
  each stage logs plain lines instead (:func:`progress_bars`).
"""

from __future__ import annotations

import contextlib
import logging
import sys
import warnings
from pathlib import Path

PACKAGE_LOGGER = "bayes_roadload"
OUTPUT_LOGGER = "bayes_roadload.cli"
LEVELS = {"quiet": logging.WARNING, "normal": logging.INFO, "verbose": logging.DEBUG}
_PACKAGE_DIR = Path(__file__).resolve().parent


class _LiveStreamHandler(logging.StreamHandler):
    """A handler writing to ``sys.stdout`` or ``sys.stderr`` as they are at each message (a
    caller may redirect them after configuration: tests, batch workers' log files)."""

    def __init__(self, stream_name: str):
        super().__init__()
        self.stream_name = stream_name

    @property
    def stream(self):
        return getattr(sys, self.stream_name)

    @stream.setter
    def stream(self, value):  # logging.StreamHandler.__init__ assigns it
        pass

    def handleError(self, record: logging.LogRecord) -> None:
        """A reader that closed the pipe (``bayes-roadload models | head``) ends the command:
        the error goes to the caller (``cli.main`` exits quietly), not a traceback per line."""
        error = sys.exc_info()[1]
        if isinstance(error, BrokenPipeError):
            raise error
        super().handleError(record)


class _OnlyOutput(logging.Filter):
    def __init__(self, output: bool):
        super().__init__()
        self.output = output

    def filter(self, record: logging.LogRecord) -> bool:
        return (record.name == OUTPUT_LOGGER) == self.output


def _handler(stream_name: str, output: bool, fmt: str) -> logging.Handler:
    h = _LiveStreamHandler(stream_name)
    h.addFilter(_OnlyOutput(output))
    h.setFormatter(logging.Formatter(fmt))
    h._bayes_roadload = True  # type: ignore[attr-defined]  # ours: replaced on reconfiguration
    return h


def configure(verbosity: str = "normal") -> None:
    """Set the ``bayes_roadload`` loggers for a command: ``verbosity`` "quiet", "normal" or
    "verbose" (:data:`LEVELS`).  Idempotent: a second call replaces the first's handlers."""
    logger = logging.getLogger(PACKAGE_LOGGER)
    for h in list(logger.handlers):
        if getattr(h, "_bayes_roadload", False):
            logger.removeHandler(h)
    logger.addHandler(_handler("stdout", True, "%(message)s"))
    logger.addHandler(_handler("stderr", False, "%(levelname).1s %(message)s"
                               if verbosity == "verbose" else "%(message)s"))
    logger.setLevel(LEVELS[verbosity])
    logger.propagate = False


def verbosity_of(quiet: bool, verbose: bool) -> str:
    """``--quiet`` / ``--verbose`` as a :data:`LEVELS` key (refuses both)."""
    if quiet and verbose:
        raise ValueError("--quiet and --verbose: give one")
    return "quiet" if quiet else "verbose" if verbose else "normal"


def _is_ours(filename: str) -> bool:
    try:
        return _PACKAGE_DIR in Path(filename).resolve().parents
    except (OSError, ValueError):
        return False


@contextlib.contextmanager
def routed_warnings():
    """Within the block, a warning raised in this package's code is logged at WARNING and one
    raised in a third-party library at DEBUG (shown with ``--verbose`` only)."""
    log = logging.getLogger(PACKAGE_LOGGER + ".warnings")

    def show(message, category, filename, lineno, file=None, line=None):
        level = logging.WARNING if _is_ours(filename) else logging.DEBUG
        where = "" if _is_ours(filename) else f" ({Path(filename).name}:{lineno})"
        log.log(level, "warning: %s%s", message, where)

    with warnings.catch_warnings():
        warnings.showwarning = show
        yield


def progress_bars(requested: bool) -> bool:
    """Draw progress bars: asked for, INFO shown, and standard error a terminal."""
    return bool(requested and logging.getLogger(PACKAGE_LOGGER).isEnabledFor(logging.INFO)
                and getattr(sys.stderr, "isatty", lambda: False)())
