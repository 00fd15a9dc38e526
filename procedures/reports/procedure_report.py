"""The Markdown report a procedure leaves beside its HDF5 file (with its PNG plots)."""

from __future__ import annotations

import logging
import math
from pathlib import Path
from typing import TYPE_CHECKING

from daq.provenance import header_lines
from procedures.reports.textfile import write_text_atomic

if TYPE_CHECKING:
    from procedures.procedure import Analysis, Procedure
    from procedures.runner import RunSummary

log = logging.getLogger(__name__)


def fmt(value: object, digits: int = 5) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    if isinstance(value, dict):
        return ", ".join(f"{k} {fmt(v, digits)}" for k, v in value.items())
    return str(value)


def stderr_text(se: float | None) -> str:
    """A standard error as printed: a NaN one (a single repetition, no spread) is no number."""
    if se is not None and not math.isfinite(se):
        return "not resolved"
    return fmt(se, 3)


def write_report(
    proc: Procedure, summary: RunSummary, analysis: Analysis | None, path: Path
) -> Path:
    stem = path.stem
    lines = [
        f"# {proc.title}",
        "",
        f"- procedure: `{proc.name}`",
        f"- file: `{summary.file.name if summary.file else '-'}`",
        f"- status: {summary.status}",
        f"- verdict: **{summary.verdict}**",
        *header_lines(summary.provenance),
    ]
    if summary.error:
        lines.append(f"- error: {summary.error}")
    lines += [
        f"- steps done: {len(summary.steps_done)} of {len(summary.steps_planned)}"
        + (
            f" ({len(summary.steps_resumed)} taken over from the resumed run)"
            if summary.steps_resumed
            else ""
        ),
        "",
    ]
    if summary.steps_planned and len(summary.steps_done) < len(summary.steps_planned):
        left = [s for s in summary.steps_planned if s not in summary.steps_done]
        lines += ["Steps not done: " + ", ".join(left) + ".", ""]
    lines += ["## Parameters", "", "| parameter | value |", "|---|---|"]
    lines += [f"| {k} | {fmt(v)} |" for k, v in summary.params.items()]
    lines.append("")
    if summary.measurements:
        lines += [
            "## Measurements",
            "",
            "| measurement | value | std. error | units | limits | result |",
            "|---|---|---|---|---|---|",
        ]
        for m in summary.measurements:
            verdict = {True: "pass", False: "**FAIL**", None: ""}[m.passed]
            lines.append(
                f"| {m.name} | {fmt(m.value, 6)} | {stderr_text(m.stderr)} | {m.units} | "
                f"{m.limits_text()} | {verdict} |"
            )
        lines.append("")
    if analysis is not None:
        if analysis.markdown:
            lines += [analysis.markdown.rstrip(), ""]
        for fig in analysis.figures:
            png = path.with_name(f"{stem}-{fig.name}.png")
            try:
                fig.draw(png)
            except Exception as exc:  # one broken plot must not lose the report
                log.error("plot %s failed: %s", fig.name, exc)
                lines += [f"(plot {fig.name} failed: {exc})", ""]
                continue
            lines += [f"![{fig.caption}]({png.name})", "", f"*{fig.caption}*", ""]
    return write_text_atomic(path, "\n".join(lines) + "\n")
