"""A worker's scratch directory that a killed worker does not leave behind for ever.

``tempfile.TemporaryDirectory`` removes its directory when the ``with`` block ends, which a
process ended by SIGTERM or SIGKILL never reaches: an interrupted campaign's pool workers are
terminated mid-run (``fbs.batch_exec.LocalPool.abort``) and each left its record, megabytes, in
the temporary directory. The directory's name carries its process's pid, and making a new one
first removes those whose process is gone - the next run on the machine tidies what a killed
one left. A pid the kernel has handed to another process since keeps its directory until that
one ends too: a directory is never removed while a process of its pid is alive.
"""

from __future__ import annotations

import contextlib
import logging
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

log = logging.getLogger(__name__)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def _owner(path: Path, prefix: str) -> int | None:
    pid, sep, _ = path.name[len(prefix) :].partition("-")
    return int(pid) if sep and pid.isdigit() else None


def sweep(prefix: str, root: Path | None = None) -> list[Path]:
    """Remove the directories ``root/<prefix><pid>-*`` whose process is gone; return them."""
    base = Path(root if root is not None else tempfile.gettempdir())
    gone = []
    for d in base.glob(f"{prefix}*-*"):
        pid = _owner(d, prefix)
        if pid is None or pid == os.getpid() or _alive(pid) or not d.is_dir():
            continue
        shutil.rmtree(d, ignore_errors=True)
        gone.append(d)
    if gone:
        log.info("removed %d scratch director(ies) left by ended processes", len(gone))
    return gone


@contextlib.contextmanager
def scratch_dir(prefix: str, root: Path | None = None) -> Iterator[Path]:
    """A new directory ``<root>/<prefix><pid>-XXXXXXXX``, removed when the block ends; the
    ones ended processes left are removed before it is made."""
    sweep(prefix, root)
    d = tempfile.mkdtemp(prefix=f"{prefix}{os.getpid()}-", dir=root)
    try:
        yield Path(d)
    finally:
        shutil.rmtree(d, ignore_errors=True)
