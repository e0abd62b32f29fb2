"""Failures of a fit that say where they happened and what to do.

A fit goes through stages (:data:`STAGES`): loading the campaign, the least-squares start, the
MAP and its Laplace covariance, NUTS warm-up and sampling, and writing the outputs.  An
unexpected exception inside one of them is re-raised by :func:`stage` as a
:class:`FitStageError` that names the stage, the run or parameter concerned when known, and a
remedy; the command line prints that one message and writes the full traceback to
``error.log`` in the output directory (:func:`write_error_log`), never to the terminal.

This module depends on nothing else in the package, so every layer may raise its errors.
"""

from __future__ import annotations

import contextlib
import traceback
from pathlib import Path
from typing import Iterator

STAGES = ("load", "lsq_start", "map", "warmup", "sampling", "output")
"""The stages of a fit, in order."""

DEFAULT_REMEDIES = {
    "load": "check the campaign files against docs/data-format.md",
    "lsq_start": "check the run named above (its speed trace must decrease); drop it with --validity reject",
    "map": "check the run or parameter named above; a model with fewer free coefficients (--model three_term) "
           "or --method lsq gives a start",
    "warmup": "more warm-up (--warmup) or a higher --target-accept; check the MAP in diagnostics.json",
    "sampling": "more warm-up (--warmup) or a higher --target-accept",
    "output": "check that --out is writable and has free space",
}
"""What to try first when a stage fails without a more specific remedy."""

ERROR_LOG = "error.log"
"""Name of the traceback file written in the output directory."""


class FitStageError(RuntimeError):
    """A fit of a valid campaign failed in one stage.

    Parameters
    ----------
    stage : one of :data:`STAGES`.
    message : what went wrong, in the user's terms.
    run : the run id concerned, when known.
    parameter : the parameter (or sample site) concerned, when known.
    remedy : what to do; defaults to the stage's :data:`DEFAULT_REMEDIES` entry.

    Not a ``ValueError``: the input was accepted, and the command line reports a numerical
    failure with its own exit code, apart from refused input.
    """

    def __init__(self, stage: str, message: str, *, run=None, parameter: str | None = None,
                 remedy: str | None = None):
        if stage not in STAGES:
            raise ValueError(f"unknown fit stage {stage!r}; expected one of {', '.join(STAGES)}")
        self.stage = stage
        self.detail = message
        self.run = run
        self.parameter = parameter
        self.remedy = remedy or DEFAULT_REMEDIES[stage]
        super().__init__(self._text())

    def _text(self) -> str:
        where = [f"stage {self.stage}"]
        if self.run is not None:
            where.append(f"run {self.run}")
        if self.parameter is not None:
            where.append(f"parameter {self.parameter}")
        return f"{', '.join(where)}: {self.detail}; remedy: {self.remedy}"


@contextlib.contextmanager
def stage(name: str, *, remedy: str | None = None, run=None, parameter: str | None = None,
          passthrough: tuple[type[BaseException], ...] | None = None) -> Iterator[None]:
    """Run a block as fit stage ``name``: an exception escaping it is re-raised as a
    :class:`FitStageError` naming the stage (chained to the original, whose traceback
    :func:`write_error_log` keeps).

    A :class:`FitStageError` and ``KeyboardInterrupt`` pass through unchanged, and so do the
    ``passthrough`` types: by default ``ValueError`` and ``FileNotFoundError`` in the
    ``"load"`` stage (refused input, exit code 2 of the command line), nothing in the others
    (there a ``ValueError``, e.g. scipy's "array must not contain infs or NaNs", is a
    numerical failure of accepted input, not a refusal)."""
    if name not in STAGES:
        raise ValueError(f"unknown fit stage {name!r}; expected one of {', '.join(STAGES)}")
    if passthrough is None:
        passthrough = (ValueError, FileNotFoundError) if name == "load" else ()
    try:
        yield
    except (FitStageError, KeyboardInterrupt, *passthrough):
        raise
    except Exception as e:  # noqa: BLE001 - re-raised with the stage named
        message = f"{type(e).__name__}: {e}".strip().rstrip(":")
        raise FitStageError(name, message, run=run, parameter=parameter, remedy=remedy) from e


def write_error_log(out_dir: str | Path | None, exc: BaseException, argv: list[str] | None = None) -> Path | None:
    """Write the full traceback of ``exc`` (with its chained causes) to ``error.log`` in
    ``out_dir``, creating the directory; returns the file, or None when ``out_dir`` is None
    or cannot be written (the caller still prints its one-line message)."""
    if out_dir is None:
        return None
    try:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        path = out / ERROR_LOG
        head = "" if argv is None else "command: bayes-roadload " + " ".join(str(a) for a in argv) + "\n\n"
        path.write_text(head + "".join(traceback.format_exception(type(exc), exc, exc.__traceback__)))
        return path
    except OSError:
        return None
