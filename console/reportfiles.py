"""The files a procedure's run leaves beside its HDF5 file, for the console to name them whole."""

from __future__ import annotations

import logging
import re
from pathlib import Path

log = logging.getLogger(__name__)

#: a Markdown image link, ``![caption](file.png)``
_IMAGE = re.compile(r"!\[[^\]]*\]\(([^)\s]+)\)")


def report_plots(report: Path | None) -> tuple[Path, ...]:
    """The plots a run's Markdown report shows (its image links, beside it), in its order: the
    report names the files actually written, a plot that failed is not among them."""
    if report is None:
        return ()
    try:
        text = report.read_text(encoding="utf-8")
    except OSError as exc:  # the report could not be read: the panel names the report alone
        log.warning("cannot read the report %s for its plots: %s", report, exc)
        return ()
    return tuple(report.parent / name for name in _IMAGE.findall(text))
