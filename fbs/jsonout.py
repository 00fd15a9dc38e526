"""Strict JSON for what the command line prints or writes: every ``--json`` object, the
campaign's curves and the gap's report.

Python's ``json`` writes a NaN or an infinity as the bare tokens ``NaN`` and ``Infinity``, which
RFC 8259 does not allow: jq, a browser or another language's parser refuses the whole object. A
number that is not finite is ``null`` here (an open interval end, a figure not measured), as in
the summary beside every run (``procedures.runner``)."""

from __future__ import annotations

from typing import Any


def dumps(obj: Any, **kwargs: Any) -> str:
    """``json.dumps`` of ``obj`` with every non-finite number ``null``; never a NaN token."""
    # on use: ``fbs --version`` imports the commands' modules, and this brings numpy
    from procedures.analysis.intervals import finite_dumps

    return finite_dumps(obj, **kwargs)
