"""What every result says about where it came from (issue 37): the rig, whether it was
simulated, the software and the time.

One dict, the same in a run file's ``/meta/provenance``, a procedure's JSON summary, its
``--json`` output and its report's header block, and in ``fbs analyze --json``:

- ``rig``: the rig's URL (a file's root attribute ``rig`` where the file states nothing more);
- ``simulated``: what the rig states about itself (``drivers.rig.Rig.simulated``), never
  guessed from the URL's text; None only for a file written before this was recorded;
- ``sim_config``: ``{"path", "sha256"}`` of the sim config file, or None (the built-in rig,
  or hardware);
- ``software``: ``{"name": "fbs-hil", "version", "commit"}``: the git commit when the package
  runs from a checkout (``git rev-parse HEAD`` in its folder), else the one pip recorded
  (``direct_url.json``), else None;
- ``time``: when the result (or the file) was made, ISO 8601 UTC.
"""

from __future__ import annotations

import datetime as _dt
import functools
import importlib.metadata
import json
import subprocess
from pathlib import Path
from typing import TYPE_CHECKING, Any

from daq.runfile import __version__

if TYPE_CHECKING:
    from daq.reader import RunFile
    from drivers.rig import Rig

#: the folder the packages are imported from (the repository root in a checkout)
_ROOT = Path(__file__).resolve().parent.parent
KEYS = ("rig", "simulated", "sim_config", "software", "time")


def utc_now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


@functools.cache
def commit() -> str | None:
    """The commit this code is at, or None where nothing says (a failure stays quiet: a
    result is not lost for want of its commit)."""
    if (_ROOT / ".git").exists():  # a checkout of its own, not a site-packages inside one
        try:
            r = subprocess.run(
                ["git", "rev-parse", "HEAD"],
                cwd=_ROOT,
                capture_output=True,
                text=True,
                timeout=5,
                check=False,
            )
            if r.returncode == 0 and r.stdout.strip():
                return r.stdout.strip()
        except (OSError, subprocess.SubprocessError):
            pass
    try:
        text = importlib.metadata.distribution("fbs-hil").read_text("direct_url.json")
        info = json.loads(text or "{}").get("vcs_info") or {}
        return str(info["commit_id"]) if "commit_id" in info else None
    except (importlib.metadata.PackageNotFoundError, ValueError, AttributeError):
        return None


def software() -> dict[str, Any]:
    return {"name": "fbs-hil", "version": __version__, "commit": commit()}


def of_rig(rig: Rig) -> dict[str, Any]:
    """The rig's part, as the rig states it; with the software and the time now."""
    return {
        "rig": rig.url,
        "simulated": bool(rig.simulated),
        "sim_config": rig.sim_config,
        "software": software(),
        "time": utc_now(),
    }


def offline(rig: str, sim_config: dict[str, str] | None) -> dict[str, Any]:
    """A file made without a rig by the simulator itself (``fbs simulate``, the gap's models)."""
    return {
        "rig": rig,
        "simulated": True,
        "sim_config": sim_config,
        "software": software(),
        "time": utc_now(),
    }


def of_file(rf: RunFile) -> dict[str, Any]:
    """Where a run file's data came from (its ``/meta/provenance``; for an older file or
    another writer's, its ``rig`` attribute and ``simulated`` None: it does not say), with
    the software and the time of whoever reads it now (an analysis is made now, by this)."""
    meta = rf.meta.get("provenance") if isinstance(rf.meta, dict) else None
    meta = meta if isinstance(meta, dict) else {}
    simulated = meta.get("simulated")
    cfg = meta.get("sim_config")
    return {
        "rig": str(meta.get("rig", rf.attrs.get("rig", ""))),
        "simulated": simulated if isinstance(simulated, bool) else None,
        "sim_config": cfg if isinstance(cfg, dict) else None,
        "software": software(),
        "time": utc_now(),
    }


def header_lines(p: dict[str, Any]) -> list[str]:
    """The Markdown report's header block."""
    said = p.get("simulated")
    sim = "**simulated**" if said else "hardware" if said is False else "not stated by the file"
    cfg = p.get("sim_config")
    sw = p.get("software") or {}
    return [
        f"- rig: `{p.get('rig')}` ({sim})"
        + (f"; sim config `{cfg['path']}` (sha256 {cfg['sha256'][:16]}...)" if cfg else ""),
        f"- software: fbs-hil {sw.get('version')}, commit {sw.get('commit') or 'unknown'}",
        f"- time: {p.get('time')}",
    ]
