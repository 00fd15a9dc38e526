"""The baseline report: each open-loop figure beside the thesis's (Ch. V B, Table 1). The
procedure is ``procedures.calibrations.baseline``; the numbers ``procedures.analysis.baseline``."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from procedures.analysis.baseline import Line


def _r(v: object, fmt: str = ".4g") -> str:
    return "-" if v is None else v if isinstance(v, str) else format(v, fmt)


def _ci(values: Mapping[str, Any], key: str, ch: str) -> str:
    iv = (values.get(f"{key}_ci95") or {}).get(ch)
    if not iv or iv[0] is None:
        return "-"
    return f"[{_r(iv[0])}, {_r(iv[1])}]"


def markdown(
    values: Mapping[str, Any],
    axis: str,
    lines: Sequence[Line],
    true_lines_hint: Sequence[float],
    reference: Mapping[str, Any],
    seconds: float,
    fs: float,
    seg_s: float,
    n_blocks: int,
) -> str:
    """The baseline's section of the report: NEA, white level, corner, pickoff rms and lines."""
    ref_nea = (reference.get("nea_urad") or {}).get(axis) or {}
    ref_corner = reference.get("flicker_corner_hz") or {}
    ref_pick = (reference.get("pickoff_rms_urad") or {}).get(axis) or {}
    resolved = values.get("resolved") or {}
    out = [
        "## Open-loop baseline",
        "",
        f"Platform clamped to the table, loops open (Ch. V B), axis {axis}, gyros spinning and caged (mode 3). "
        f"Record: {seconds:.0f} s at {fs:g} Hz; Welch, Hann segments of {seg_s:g} s, 50 % overlap, in "
        f"{n_blocks} blocks; 95 % intervals by a delete-one jackknife over the blocks.",
        "",
        f"| figure | channel | measured | 95 % interval | {reference.get('source', 'reference')} |",
        "|---|---|---|---|---|",
    ]
    rows = [
        ("NEA 0.1-100 Hz (urad rms)", "nea_urad", ref_nea),
        ("white level (urad/sqrt(Hz))", "white_urad_per_rtHz", {}),
        ("1/f corner (Hz)", "flicker_corner_hz", ref_corner),
        ("pickoff rms (urad)", "pickoff_rms_urad", ref_pick),
    ]
    for label, key, ref in rows:
        for ch, v in (values.get(key) or {}).items():
            note = "" if (resolved.get(key) or {}).get(ch, True) else " (not resolved)"
            out.append(
                f"| {label} | {ch} | {_r(v)}{note} | {_ci(values, key, ch)} | {_r(ref.get(ch))} |"
            )
    out += [
        "",
        "Pickoff lines found (Fig. 33: a 71 Hz pair 0.8 Hz apart, 102 Hz, 187 Hz; the exact "
        "frequencies vary from unit to unit):",
        "",
        "| frequency (Hz) | 95 % interval (Hz) | amplitude (urad) | peak over local median |",
        "|---|---|---|---|",
    ]
    for ln in lines:
        lo, hi = ln.ci95_hz
        out.append(
            f"| {ln.freq_hz:.3f} | [{lo:.3f}, {hi:.3f}] | {ln.amplitude_urad:.3g} | {ln.ratio:.0f} |"
        )
    if not lines:
        out.append("| none | - | - | - |")
    out += ["", f"Thesis lines (Fig. 33): {', '.join(f'{f:g}' for f in true_lines_hint)} Hz.", ""]
    return "\n".join(out)
