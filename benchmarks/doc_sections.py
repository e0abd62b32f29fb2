"""The one way the benchmark scripts regenerate a section of a docs page: the text between a
begin and an end marker is replaced, the markers kept."""

from __future__ import annotations

import re
from pathlib import Path


def replace_section(doc: Path, begin: str, end: str, text: str, *, heading: str | None = None) -> None:
    """Write ``text`` between the markers ``begin`` and ``end`` of ``doc``.  Without the
    markers: append them under ``heading`` when one is given, else refuse (SystemExit)."""
    body = doc.read_text()
    block = f"{begin}\n{text}{end}"
    pattern = re.compile(re.escape(begin) + ".*?" + re.escape(end), re.S)
    if pattern.search(body):
        doc.write_text(pattern.sub(lambda _: block, body))
    elif heading is not None:
        doc.write_text(body.rstrip("\n") + f"\n\n{heading}\n\n{block}\n")
    else:
        raise SystemExit(f"{doc}: markers {begin} ... {end} not found")
