"""Load and save a campaign directory of any kind, through one registry of data kinds.

A campaign directory holds one data file, whose name says the kind of campaign, beside
``vehicle.toml`` and, for simulated campaigns, ``truth.json`` (``docs/data-format.md``).
Each kind is a module of this package that follows :class:`CampaignKind`; :data:`DATA_KINDS`
lists them.  :func:`load_campaign` finds the kind by its files and :func:`save_campaign` by the
campaign's ``kind``: a new kind is its own module plus one line in :data:`DATA_KINDS`.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Any, Protocol

from . import distances, intervals, spindown, steady, traces
from .checks import TRUTH_FILE, CampaignError, write_atomically


class CampaignKind(Protocol):
    """What a module of one kind of campaign data provides (module-level names).

    Attributes
    ----------
    KIND : str
        The kind's name, e.g. ``"traces"``; the ``kind`` class attribute of its campaigns.
    FILES : tuple of str
        The data file names whose presence in a directory identifies the kind (the first is
        the default one written), e.g. ``("runs.csv", "runs.parquet")``.
    DESCRIPTION : str
        What the data are, a plural noun phrase for messages ("speed-gate interval times",
        "spin-down campaigns", ...).
    OPTIONS : tuple of str
        Names of the keyword arguments :meth:`load` takes beyond the directory (measured
        constants that may stand in for the file's), e.g. ``("wheel_inertia_kgm2",
        "rolling_radius_m")``; empty for most kinds.
    OPTIONAL_FILES : tuple of str
        Files beside the data file that the kind reads when present (speed traces: the track
        survey ``track.csv``); another kind's directory holding one is refused, as its data
        would be silently ignored.  Empty for most kinds.
    """

    KIND: str
    FILES: tuple[str, ...]
    DESCRIPTION: str
    OPTIONS: tuple[str, ...]
    OPTIONAL_FILES: tuple[str, ...]

    def load(self, root: str | os.PathLike, **options: Any) -> Any:
        """The validated campaign of a directory holding one of :attr:`FILES`; refusals are
        :class:`~bayes_roadload.data.checks.CampaignError` naming file, column and row."""

    def files(self, campaign: Any, fmt: str = "csv") -> dict[str, str | bytes]:
        """The files of the campaign's directory, name -> text (bytes for a binary file),
        validated first (the campaign's table is replaced by its normalised copy); a
        ``fmt`` the kind does not write is refused with ValueError."""


DATA_KINDS: tuple[CampaignKind, ...] = (
    traces,
    intervals,
    distances,
    spindown,
    steady,
)
"""The kinds of campaign data, in the order their files are listed in messages."""

_BY_NAME: dict[str, CampaignKind] = {k.KIND: k for k in DATA_KINDS}

DATA_FILES: tuple[str, ...] = tuple(f for k in DATA_KINDS for f in k.FILES)
"""Every file name that identifies a kind: a saved directory keeps only its own."""

OPTIONAL_FILES: tuple[str, ...] = tuple(dict.fromkeys(f for k in DATA_KINDS for f in k.OPTIONAL_FILES))
"""Every optional file some kind reads beside its data file (:attr:`CampaignKind.OPTIONAL_FILES`)."""


def data_kind(kind: str) -> CampaignKind:
    """The module of the data kind named ``kind`` (a campaign's ``kind`` attribute)."""
    try:
        return _BY_NAME[kind]
    except KeyError:
        raise ValueError(f"unknown campaign kind {kind!r}; known: {', '.join(_BY_NAME)}") from None


def kind_of(campaign: Any) -> CampaignKind:
    """The module of a campaign's data kind (by its ``kind`` class attribute)."""
    if not hasattr(campaign, "kind"):
        raise TypeError(f"{type(campaign).__name__} is not a campaign (it has no kind)")
    return data_kind(campaign.kind)


def find_kind(root: str | os.PathLike) -> CampaignKind:
    """The kind of the campaign directory ``root``, by the data files present; refused when
    it is not a directory, holds the files of two kinds, or none."""
    root = Path(root)
    if not root.is_dir():
        raise CampaignError(f"{root}: not a campaign directory")
    present = {k.KIND: [f for f in k.FILES if (root / f).exists()] for k in DATA_KINDS}
    found = [k for k in DATA_KINDS if present[k.KIND]]
    if len(found) > 1:
        names = [f for k in found for f in present[k.KIND]]
        raise CampaignError(f"{root}: {' and '.join(names)} present (ambiguous campaign kind): one data file "
                            "per campaign directory")
    if not found:
        first, *others = DATA_KINDS
        alternatives = list(first.FILES[1:]) + [f"{f} for {k.DESCRIPTION}" for k in others for f in k.FILES]
        raise CampaignError(f"{root}: {first.FILES[0]} (or {', or '.join(alternatives)}) is missing")
    kind = found[0]
    foreign = [f for f in OPTIONAL_FILES if f not in kind.OPTIONAL_FILES and (root / f).exists()]
    if foreign:
        readers = [k for k in DATA_KINDS if foreign[0] in k.OPTIONAL_FILES]
        raise CampaignError(f"{root / foreign[0]}: read with {' and '.join(k.DESCRIPTION for k in readers)} "
                            f"({', '.join(f for k in readers for f in k.FILES)}) only; "
                            f"the {kind.DESCRIPTION} of {kind.FILES[0]} would ignore it: remove it")
    return kind


def load_campaign(path: str | os.PathLike, **options: Any) -> Any:
    """Load and validate a campaign directory of any kind (see ``docs/data-format.md``).

    The kind is found by the data file present: a
    :class:`~bayes_roadload.data.traces.Campaign` of speed traces (``runs.csv`` /
    ``runs.parquet``), an :class:`~bayes_roadload.data.intervals.IntervalCampaign` of speed-gate
    interval times (``intervals.csv``), a :class:`~bayes_roadload.data.distances.DistanceCampaign`
    of distance-time records (``distances.csv``), a
    :class:`~bayes_roadload.data.spindown.SpindownCampaign` of wheel spin-downs
    (``spindown.csv``) or a :class:`~bayes_roadload.data.steady.SteadyCampaign` of steady-state
    torque tests (``steady.csv``).

    ``options`` go to the kind's loader (its ``OPTIONS``, e.g. the spin-down's
    ``wheel_inertia_kgm2`` and ``rolling_radius_m``); an option left None is not given, one
    given to a kind that does not take it is refused with ValueError.
    """
    unknown = [name for name in options if not any(name in k.OPTIONS for k in DATA_KINDS)]
    if unknown:
        raise TypeError(f"load_campaign() got an unexpected keyword argument {unknown[0]!r}")
    kind = find_kind(path)
    given = {name: value for name, value in options.items() if value is not None}
    if any(name not in kind.OPTIONS for name in given):
        takers = [k for k in DATA_KINDS if any(name in k.OPTIONS for name in given)]
        flags = " / ".join(f"--{name.replace('_', '-')}" for k in takers for name in k.OPTIONS)
        raise ValueError(f"{flags} apply to "
                         + " and ".join(f"{k.DESCRIPTION} ({', '.join(k.FILES)})" for k in takers) + " only")
    return kind.load(path, **given)


def save_campaign(campaign: Any, path: str | os.PathLike, fmt: str = "csv") -> Path:
    """Validate and write a campaign directory of any kind; nothing is written if validation
    fails.

    Files are written to a temporary directory beside ``path`` and moved into place; the data
    files of every other kind (and a ``truth.json`` or ``track.csv`` the campaign no longer has)
    are removed, so the directory reads back as this campaign.  ``fmt`` is "csv" or, for speed traces,
    "parquet".
    """
    return write_atomically(path, kind_of(campaign).files(campaign, fmt), stale=DATA_FILES + (TRUTH_FILE,) + OPTIONAL_FILES)


def campaign_sha256(path: str | os.PathLike) -> str:
    """SHA-256 of a campaign directory's content: the names and bytes of its top-level files
    (hidden files left out), in name order; what a fit records of the data it saw."""
    h = hashlib.sha256()
    for f in sorted(p for p in Path(path).iterdir() if p.is_file() and not p.name.startswith(".")):
        h.update(f.name.encode() + b"\0" + f.read_bytes() + b"\0")
    return h.hexdigest()
