"""Resume: what an earlier run of a procedure recorded as done, and the run file names.

``load_resume`` reads an aborted run's ``step-done`` events: its completed data steps are taken
over by the next run (their results and spans re-recorded as ``step-done`` events marked
``resumed``), its setup steps run again, the rest run normally. ``load_resume(...,
complete_ok=True)`` of a complete file moves nothing: its analysis runs again and its summary and
report are written anew (an analysis or report that was interrupted or failed after a complete
acquisition). A procedure never overwrites an earlier run (``next_free``).
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from daq.reader import Event, RunFile
from daq.runfile import STATUS_COMPLETE
from procedures.procedure import EVENT_STEP_DONE, Procedure, ProcedureError, Span
from procedures.stepresult import StepResult, StepResultError


def next_free(out_dir: Path, stem: str, suffix: str = ".h5") -> Path:
    """``stem.h5``, else ``stem-2.h5``, ...: a procedure never overwrites an earlier run."""
    path = out_dir / f"{stem}{suffix}"
    n = 2
    while path.exists() or path.with_suffix(".json").exists():
        path = out_dir / f"{stem}-{n}{suffix}"
        n += 1
    return path


def run_file_for(out_dir: Path, stem: str, resume: Resumed | None = None) -> Path:
    """The file ``run_procedure`` will write: a complete run analysed again keeps its own;
    otherwise (a new run, or an aborted one resumed) the next free name."""
    return resume.path if resume is not None and resume.complete else next_free(out_dir, stem)


# ---------------------------------------------------------------------------- resume
@dataclass
class Resumed:
    path: Path
    procedure: str
    params: dict[str, Any]
    results: dict[str, StepResult]
    #: where the completed data steps' samples are (in that file, or in one it resumed)
    spans: dict[str, Span] = field(default_factory=dict)
    #: the run is complete: ``run_procedure`` analyses it again, the rig is not touched
    complete: bool = False
    #: the earlier results the run was made with (its /meta/prior), for analysing it again
    prior: dict[str, Any] = field(default_factory=dict)
    #: the steps that run itself took over from a run it resumed
    taken_over: list[str] = field(default_factory=list)


def load_resume(
    path: str | Path, procedure: type[Procedure[Any]], *, complete_ok: bool = False
) -> Resumed:
    """The completed steps of an aborted run of ``procedure`` (from its ``step-done`` events),
    each result read back as the type its step names (the plan made with the run's parameters);
    with ``complete_ok`` a complete run too (``Resumed.complete``: to be analysed again)."""
    path = Path(path)
    with RunFile(path) as rf:
        status = rf.status
        meta = rf.meta
        events = rf.events
    info = meta.get("procedure") if isinstance(meta, dict) else None
    if not isinstance(info, dict) or "name" not in info:
        raise ProcedureError(f"--resume {path}: not a procedure run (no /meta/procedure)")
    if info["name"] != procedure.name:
        raise ProcedureError(
            f"--resume {path}: that file is a {info['name']!r} run, not {procedure.name!r}"
        )
    if status == STATUS_COMPLETE and not complete_ok:
        raise ProcedureError(f"--resume {path}: that run is complete; nothing to resume")
    params = dict(info.get("params", {}))
    try:
        plan = procedure(procedure.params_from(params)).plan()
    except ValueError as exc:
        raise ProcedureError(f"--resume {path}: its parameters do not make a plan: {exc}") from None
    kinds = {s.name: s.result for s in plan}
    results, spans = steps_done(path, events, kinds)
    unplanned = sorted(set(_done(events)) - set(kinds))
    if unplanned:
        raise ProcedureError(
            f"--resume {path}: step(s) {', '.join(map(repr, unplanned))} done there are not in "
            f"the plan its parameters make now"
        )
    prior = meta.get("prior")
    return Resumed(
        path,
        procedure.name,
        params,
        results,
        spans,
        complete=status == STATUS_COMPLETE,
        prior=dict(prior) if isinstance(prior, dict) else {},
        taken_over=[name for name, d in _done(events).items() if "resumed" in d],
    )


def steps_done(
    path: Path, events: Iterable[Event], kinds: Mapping[str, type[StepResult]]
) -> tuple[dict[str, StepResult], dict[str, Span]]:
    """The results and data spans of the steps a run file records as done (its ``step-done``
    events), by step name, of the steps named in ``kinds`` (each result read back as its type
    there; other steps left out): what a resume takes over, or a re-analysis of a finished run
    reads."""
    results: dict[str, StepResult] = {}
    spans: dict[str, Span] = {}
    for name, item in _done(events, path).items():
        if name not in kinds:
            continue
        try:
            results[name] = kinds[name].from_json(item.get("result", {}))
        except StepResultError as exc:
            raise ProcedureError(f"{path}: step {name!r}: {exc}") from None
        if item.get("span"):
            spans[name] = Span.from_json(item["span"], path)
    return results, spans


def _done(events: Iterable[Event], path: Path | None = None) -> dict[str, dict[str, Any]]:
    """The ``step-done`` events' JSON, by step name."""
    out: dict[str, dict[str, Any]] = {}
    for e in events:
        if e.kind == EVENT_STEP_DONE:
            try:
                item = json.loads(e.text)
            except json.JSONDecodeError:
                raise ProcedureError(
                    f"{path or 'the run file'}: a step-done event at {e.time_s:.3f} s is not "
                    f"JSON (cut at {len(e.text)} bytes?)"
                ) from None
            out[item["step"]] = item
    return out
