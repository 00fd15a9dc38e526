"""A text output (a run's JSON summary, its report) written whole or not at all.

Written to a temporary name beside it and renamed over it (``os.replace``, atomic on POSIX):
a full disk or a kill mid-write leaves the old file or no file, never a truncated one (a
0-byte summary JSON was found after a disk filled under ``fbs run``).
"""

from __future__ import annotations

import os
from pathlib import Path


def write_text_atomic(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` whole; on any error nothing is left behind and the
    error is raised."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path
