"""A worker's scratch directory that a killed worker does not leave behind for ever.

``tempfile.TemporaryDirectory`` removes its directory when the ``with`` block ends, which a
process ended by SIGTERM or SIGKILL never reaches: an interrupted campaign's pool workers are
terminated mid-run (``fbs.batch_exec.LocalPool.abort``) and each left its record, megabytes, in
the temporary directory. The directory's name carries its host's name and its process's pid,
and making a new one first removes this host's whose process is gone - the next run on the
machine tidies what a killed one left. A pid the kernel has handed to another process since
keeps its directory until that one ends too: a directory is never removed while a process of
its pid is alive. The host's name keeps the judgement to processes this one can see (another
machine or container sharing the temporary directory has its own).
"""

from __future__ import annotations

import contextlib
import glob
import logging
import os
import re
import shutil
import socket
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


def _mine(prefix: str) -> str:
    """The name's start for this host: ``<prefix><host>-``."""
    return f"{prefix}{socket.gethostname()}-"


def _owner(path: Path, mine: str) -> int | None:
    """The pid in ``<mine><pid>-<mkdtemp's suffix>`` (no dash in the suffix: a host named
    like this one with "-1" after it is not this one)."""
    m = re.fullmatch(r"(\d+)-[^-]+", path.name[len(mine) :])
    return int(m.group(1)) if m else None


def sweep(prefix: str, root: Path | None = None) -> list[Path]:
    """Remove this host's directories ``root/<prefix><host>-<pid>-*`` whose process is gone;
    return them."""
    base = Path(root if root is not None else tempfile.gettempdir())
    mine = _mine(prefix)
    gone = []
    for d in base.glob(f"{glob.escape(mine)}*-*"):
        pid = _owner(d, mine)
        if pid is None or pid == os.getpid() or _alive(pid) or not d.is_dir():
            continue
        shutil.rmtree(d, ignore_errors=True)
        gone.append(d)
    if gone:
        log.info("removed %d scratch director(ies) left by ended processes", len(gone))
    return gone


@contextlib.contextmanager
def scratch_dir(prefix: str, root: Path | None = None) -> Iterator[Path]:
    """A new directory ``<root>/<prefix><host>-<pid>-XXXXXXXX``, removed when the block ends;
    the ones ended processes of this host left are removed before it is made."""
    sweep(prefix, root)
    d = tempfile.mkdtemp(prefix=f"{_mine(prefix)}{os.getpid()}-", dir=root)
    try:
        yield Path(d)
    finally:
        shutil.rmtree(d, ignore_errors=True)
