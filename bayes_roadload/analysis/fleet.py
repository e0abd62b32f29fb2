"""Fit every campaign under a directory -- a fleet of vehicles, a season of tests -- through
the batch door (:mod:`bayes_roadload.analysis.batch`).

Each campaign found by :func:`find_campaigns` becomes one :class:`FleetJob`, which runs the
single-campaign ``fit`` command itself (``fit CAMPAIGN --out OUT/<relative path> [fit
options]``) in a worker: the outputs of a fleet fit are those of single fits by construction.
The command's printed output goes to ``fit.log`` beside its outputs, and a completion marker
``batch_done.json`` holds the campaign's row of the combined table.

``OUT/batch.csv`` has one row per campaign (:data:`TABLE_COLUMNS`, then the posterior mean,
sd and 2.5 / 97.5 % quantiles of the key quantities read from each ``summary.csv``).  A
campaign's failure is a row with its ``status`` and ``error``; the others go on.  A run is
resumable: a campaign whose marker was written with the same fit options is not fitted again
and its row is reused.

The fit command is given to :func:`fit_fleet` (``fit_command``): the command-line layer passes
its own ``main``, and this module never imports it.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import time
import traceback
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Callable, Sequence

import pandas as pd

from ..data.checks import CampaignError
from ..data.io import DATA_FILES, find_kind
from .batch import batch_client, batch_map

MARKER_FILE = "batch_done.json"
"""Completion marker of a campaign's output directory (its row of the combined table)."""

LOG_FILE = "fit.log"
"""The fit command's standard output and error, in the campaign's output directory."""

TABLE_FILE = "batch.csv"
"""The combined table, in the fleet's output directory."""

FIT_STATUS = {0: "passed", 2: "refused", 3: "gates failed"}
"""Status of a campaign by the exit code of the ``fit`` command: 0 fitted and every
diagnostic gate passed, 2 the data or options were refused (the message is in ``error``),
3 fitted but a diagnostic gate failed.  Anything else (an exception, a killed worker) is
``"error"``."""

FINISHED_CODES = frozenset(FIT_STATUS)
"""Exit codes after which a campaign is finished (a marker is written; a rerun skips it)."""

TABLE_COLUMNS = ("campaign", "kind", "rc", "status", "error", "wall_s", "started_utc")
"""The leading columns of ``batch.csv``: the campaign's path relative to the fleet root, its
data kind (empty when the directory is refused before a kind is known), the fit command's exit
code, the status (:data:`FIT_STATUS`), the last line of the refusal or error, the wall time of
the fit (s) and when it started (ISO 8601, UTC)."""

SUMMARY_STATISTICS = ("mean", "sd", "q2.5", "q97.5")
"""Columns of ``summary.csv`` copied into ``batch.csv`` as ``<quantity>_<statistic>``."""

KEY_DERIVED = ("F50_N", "F0_N", "F1_N_per_kph", "F2_N_per_kph2")
"""Derived road-load quantities copied into ``batch.csv`` besides the free parameters
(``fit.json`` ``free``); a summary without ``fit.json`` contributes every row."""


def find_campaigns(root: str | os.PathLike, *, exclude: Sequence[str | os.PathLike] = ()) -> list[Path]:
    """Every campaign directory under ``root`` (``root`` itself included), sorted by path.

    A campaign directory holds a data file of one of the registered kinds
    (:data:`bayes_roadload.data.io.DATA_FILES`); directories below a campaign directory, hidden
    directories and the ``exclude`` directories (e.g. the fleet's own output directory) are
    not searched.
    """
    root = Path(root)
    if not root.is_dir():
        raise CampaignError(f"{root}: not a directory")
    skip = {Path(e).resolve() for e in exclude}
    found: list[Path] = []
    for here, dirs, files in os.walk(root):
        here_path = Path(here)
        if any(f in DATA_FILES for f in files):
            found.append(here_path)
            dirs[:] = []
            continue
        dirs[:] = sorted(d for d in dirs if not d.startswith(".") and (here_path / d).resolve() not in skip)
    return sorted(found)


def _relative_name(campaign: Path, root: Path) -> str:
    rel = campaign.relative_to(root).as_posix()
    return campaign.resolve().name if rel == "." else rel


def _last_line(text: str) -> str | None:
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    return lines[-1][:500] if lines else None


def summary_columns(out_dir: str | os.PathLike) -> dict[str, float]:
    """``<quantity>_<statistic>`` of the key quantities of a fit's ``summary.csv``: the free
    parameters listed in ``fit.json`` and :data:`KEY_DERIVED` (every row when there is no
    ``fit.json`` with ``free``), statistics :data:`SUMMARY_STATISTICS`; empty when the fit
    wrote no summary."""
    out = Path(out_dir)
    if not (out / "summary.csv").is_file():
        return {}
    summary = pd.read_csv(out / "summary.csv")
    free = None
    if (out / "fit.json").is_file():
        free = json.loads((out / "fit.json").read_text()).get("free")
    keep = summary["parameter"].isin(list(free) + list(KEY_DERIVED)) if free else slice(None)
    cols: dict[str, float] = {}
    for _, row in summary[keep].iterrows():
        for stat in SUMMARY_STATISTICS:
            if stat in summary:
                cols[f"{row['parameter']}_{stat}"] = float(row[stat])
    return cols


@dataclass(frozen=True)
class FleetJob:
    """One campaign of a fleet: ``fit_command(["fit", campaign_dir, "--out", out_dir, "--force",
    *fit_args])`` with its printed output captured in ``out_dir/fit.log``.

    Parameters
    ----------
    name : str
        The campaign's path relative to the fleet root (the ``campaign`` column).
    campaign_dir, out_dir : str
    fit_args : tuple of str
        Options of the ``fit`` command.
    fit_command : callable
        The command-line entry point, ``fit_command(argv) -> exit code`` (picklable: a
        module-level function such as ``bayes_roadload.cli.main``).
    """

    name: str
    campaign_dir: str
    out_dir: str
    fit_args: tuple[str, ...]
    fit_command: Callable[[list[str]], int]

    def argv(self) -> list[str]:
        """The command line of this campaign's fit."""
        return ["fit", self.campaign_dir, "--out", self.out_dir, "--force", *self.fit_args]  # the fleet owns out_dir

    def previous(self) -> dict[str, Any] | None:
        """The row of a finished earlier fit with the same options, or None."""
        marker = Path(self.out_dir) / MARKER_FILE
        if not marker.is_file():
            return None
        try:
            doc = json.loads(marker.read_text())
        except (OSError, ValueError):
            return None
        if doc.get("fit_args") != list(self.fit_args) or doc.get("rc") not in FINISHED_CODES:
            return None
        return doc.get("row")

    def run(self) -> dict[str, Any]:
        """Fit the campaign (or reuse a finished earlier fit) and return its row of
        ``batch.csv``; never raises for a failure of the fit."""
        previous = self.previous()
        if previous is not None:
            return previous
        out = Path(self.out_dir)
        out.mkdir(parents=True, exist_ok=True)
        (out / MARKER_FILE).unlink(missing_ok=True)
        try:
            kind = find_kind(self.campaign_dir).KIND
        except CampaignError:
            kind = None  # the fit command refuses the directory with its own message
        started = datetime.now(timezone.utc).isoformat(timespec="seconds")
        t0 = time.perf_counter()
        rc: int | None
        error = None
        with open(out / LOG_FILE, "w") as log, contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
            try:
                rc = int(self.fit_command(self.argv()) or 0)
            except SystemExit as exc:  # argparse and the command's own exits
                rc = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
                if not isinstance(exc.code, (int, type(None))):
                    print(exc.code, file=log)
            except Exception:  # noqa: BLE001 - one campaign's failure is its row, not the fleet's
                rc = None
                log.write(traceback.format_exc())
        wall = time.perf_counter() - t0
        status = FIT_STATUS.get(rc, "error") if rc is not None else "error"
        if status in ("refused", "error"):
            error = _last_line((out / LOG_FILE).read_text())
        row: dict[str, Any] = {"campaign": self.name, "kind": kind, "rc": rc, "status": status, "error": error,
                               "wall_s": round(wall, 3), "started_utc": started}
        row.update(summary_columns(out))
        if rc in FINISHED_CODES:
            doc = {"campaign_dir": self.campaign_dir, "fit_args": list(self.fit_args), "rc": rc, "row": row}
            (out / MARKER_FILE).write_text(json.dumps(doc, indent=2) + "\n")
        return row


def _error_row(job: FleetJob, exc: BaseException, tb: str) -> dict[str, Any]:
    """The row of a campaign whose job raised outside the fit (e.g. its worker died)."""
    return {"campaign": job.name, "kind": None, "rc": None, "status": "error",
            "error": f"{type(exc).__name__}: {exc}"[:500]}


def _run_fleet_job(job: FleetJob) -> dict[str, Any]:
    return job.run()


def combined_table(rows: Sequence[dict[str, Any]]) -> pd.DataFrame:
    """``batch.csv`` from the campaigns' rows: :data:`TABLE_COLUMNS` first, then the summary
    columns in order of first appearance, one row per campaign sorted by ``campaign``."""
    table = pd.DataFrame.from_records(list(rows))
    for col in TABLE_COLUMNS:
        if col not in table:
            table[col] = None
    rest = [c for c in table.columns if c not in TABLE_COLUMNS]
    table = table[list(TABLE_COLUMNS) + rest]
    if not table.empty:
        table = table.sort_values("campaign", kind="stable").reset_index(drop=True)
    table["rc"] = table["rc"].astype("Int64")
    return table


def fit_fleet(root: str | os.PathLike, out: str | os.PathLike, fit_args: Sequence[str] = (), *,
              fit_command: Callable[[list[str]], int], client: Any | None = None,
              progress: bool = True) -> pd.DataFrame:
    """Fit every campaign under ``root`` into ``out/<relative path>`` and write
    ``out/batch.csv``.

    Parameters
    ----------
    root : path
        Directory searched by :func:`find_campaigns` (``out`` is excluded from the search).
    out : path
        Output directory: one subdirectory per campaign (the ``fit`` outputs, ``fit.log``,
        ``batch_done.json``) and ``batch.csv``.
    fit_args : sequence of str
        Options of the ``fit`` command given to every campaign, e.g. ``["--method", "lsq"]``.
    fit_command : callable
        The command-line entry point (``bayes_roadload.cli.main``).
    client : distributed.Client, optional
        Where the fits run (:func:`~bayes_roadload.analysis.batch.batch_client`); ``None``: one
        after the other in this process.
    progress : bool
        One progress bar over the campaigns, with the time left.

    Returns
    -------
    pandas.DataFrame
        The combined table written to ``out/batch.csv`` (:func:`combined_table`); it is also
        rewritten as campaigns finish.
    """
    root, out = Path(root), Path(out)
    campaigns = find_campaigns(root, exclude=[out])
    if not campaigns:
        raise CampaignError(f"{root}: no campaign directory below it (none holds {', '.join(DATA_FILES)})")
    out.mkdir(parents=True, exist_ok=True)
    jobs = []
    for c in campaigns:
        name = _relative_name(c, root)
        jobs.append(FleetJob(name, str(c), str(out / name), tuple(str(a) for a in fit_args), fit_command))
    done: list[dict[str, Any]] = []

    def checkpoint(row: dict[str, Any]) -> None:
        done.append(row)
        combined_table(done).to_csv(out / TABLE_FILE, index=False)

    rows = batch_map(_run_fleet_job, jobs, client, progress=progress, desc="campaigns", on_result=checkpoint,
                     on_error=_error_row)
    table = combined_table(rows)
    table.to_csv(out / TABLE_FILE, index=False)
    return table


# --------------------------------------------------------------------------- command line

class _PassThrough(argparse.Action):
    """Records an option of the ``fit`` command as given (after argparse has checked its type
    and choices) in ``namespace.fit_args``."""

    def __call__(self, parser, namespace, values, option_string=None):
        given = list(getattr(namespace, "fit_args", None) or [])
        given.append(option_string)
        if values is not None and self.nargs != 0:
            given.extend(str(v) for v in (values if isinstance(values, list) else [values]))
        namespace.fit_args = given


_NOT_PASSED = {"--out", "-h", "--help"}


def add_batch_parser(subparsers, fit_command: Callable[[list[str]], int],
                     fit_parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Add the ``batch`` command to a command line's subparsers.

    ``bayes-roadload batch CAMPAIGNS_DIR --out DIR [--workers N] [--scheduler ADDR] [fit
    options]``: every option of the ``fit`` command (``fit_parser``) but ``--out`` is accepted
    and passed to each campaign's fit as given; ``fit_command`` runs a fit (the command line's
    ``main``).
    """
    p = subparsers.add_parser(
        "batch", help="fit every campaign under a directory (a fleet, a season of tests) on a Dask cluster; "
                      "resumable; combined table batch.csv",
        description="Fit every campaign directory under CAMPAIGNS_DIR exactly as `fit` does (outputs in "
                    "OUT/<relative path>, the fit's printed output in fit.log) and write OUT/batch.csv. "
                    "Campaigns finished by an earlier run with the same fit options are skipped; one "
                    "campaign's failure is its row of the table. Fit options are passed through to `fit`.")
    p.add_argument("campaigns", metavar="CAMPAIGNS_DIR")
    p.add_argument("--out", required=True, help="output directory: one fit per campaign and batch.csv")
    p.add_argument("--workers", type=int, default=None,
                   help="worker processes of the local Dask cluster (default: the usable cores; 1: in this "
                        "process, no cluster)")
    p.add_argument("--scheduler", default=None, metavar="ADDR",
                   help="address of a running Dask scheduler, e.g. tcp://10.0.0.5:8786, instead of a local "
                        "cluster (its workers need bayes-roadload installed)")
    fit_group = p.add_argument_group("fit options", "passed to `fit` for every campaign")
    quiet = []
    for action in fit_parser._actions:  # argparse keeps a parser's options there (no public accessor)
        if not action.option_strings or _NOT_PASSED & set(action.option_strings):
            continue
        if "--no-progress" in action.option_strings:
            quiet = ["--no-progress"]  # the batch shows its own progress bar
        plain = action.choices is None and action.nargs != 0
        fit_group.add_argument(*action.option_strings, dest=f"fit_{action.dest}", action=_PassThrough,
                               nargs=action.nargs, choices=action.choices, type=action.type,
                               metavar=action.metavar or (action.dest.upper() if plain else None), help=action.help)
    p.set_defaults(func=cmd_batch, fit_args=[], fit_command=fit_command, fit_quiet=quiet)
    return p


def cmd_batch(args: argparse.Namespace) -> int:
    """The ``batch`` command: :func:`fit_fleet` on a :func:`batch_client`; prints the count of
    each status and returns 0 when every campaign passed, else the exit code of the ``fit``
    command shared by the failures when they share one (2 refused, 3 gates failed), else 1."""
    fit_args = list(args.fit_args) + [a for a in args.fit_quiet if a not in args.fit_args]
    out = Path(args.out)
    quiet = bool(getattr(args, "quiet", False))  # -q: no progress, no summary (batch.csv is written)
    say = (lambda text: None) if quiet else (lambda text: print(text, flush=True))
    with batch_client(args.workers, args.scheduler) as client:
        where = "in this process" if client is None else f"on the Dask cluster at {client.scheduler_info()['address']}"
        say(f"Fitting the campaigns under {args.campaigns} {where} into {out} ...")
        table = fit_fleet(args.campaigns, out, fit_args, fit_command=args.fit_command, client=client,
                          progress=not quiet)
    counts = table["status"].value_counts()
    say(f"\n{len(table)} campaigns: " + ", ".join(f"{n} {s}" for s, n in counts.items()))
    for _, r in table[table["status"] != "passed"].iterrows():
        say(f"  {r['campaign']}: {r['status']}" + (f" ({r['error']})" if isinstance(r["error"], str) else ""))
    say(f"wrote {out / TABLE_FILE}")
    failed = table[table["status"] != "passed"]
    if failed.empty:
        return 0
    codes = set(failed["rc"].dropna().astype(int))
    return codes.pop() if len(codes) == 1 and failed["rc"].notna().all() else 1
