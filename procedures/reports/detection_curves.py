"""The detection curves of ``fbs campaign gap`` written out: a Markdown table and a plot.

The curves are ``procedures.analysis.gap.detection.curves``'s dict (also ``curves.json``); this
module only presents them.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any


def _pct(x: float | None) -> str:
    return "-" if x is None else f"{100 * x:+.1f} %"


def _ci(iv: Any) -> str:
    return "-" if iv is None else f"{iv[0]:.2f}-{iv[1]:.2f}"


def curves_markdown(cv: dict[str, Any]) -> str:
    """The curves as a Markdown table docs can quote (``curves.md``)."""
    meta = cv["campaign"]
    effect, param = meta["effect"], meta["grid"]["param"]
    shown = [param] + [
        k for k in (cv["curve"][0]["param_error"] if cv["curve"] else {}) if k != param
    ]
    rec = meta.get("record", {})
    chans = ", ".join(f"{k} {v:g} V" for k, v in meta.get("channels_V", {}).items())
    fixed = ", ".join(f"{k} = {v:g}" for k, v in meta.get("fixed", {}).items()) or "none"
    lines = [
        f"# Detection curve: `{effect}` over `{param}`",
        "",
        f"Record: {rec.get('duration_s', 0):g} s at {rec.get('rate_hz', 0):g} Hz, Mode {rec.get('mode')}, "
        f"axis {rec.get('axis')} ({chans}); other parameters: {fixed}; "
        + ("seed 1." if meta.get("seeds") == 1 else f"seeds 1-{meta.get('seeds')}."),
        f"Made by `{meta.get('command', '')}`"
        + (
            ""
            if cv["complete"]
            else f" (incomplete: {cv['done'] - cv['errors']} of {cv['runs']} runs have a result)"
        )
        + ".",
        "",
        "P: share of the runs analysed in which the workflow named the effect first, with its 95 % Wilson "
        "interval; errors: fitted / true - 1 over those runs, median [16th, 84th percentile].",
        "",
        "| "
        + " | ".join(
            [f"`{param}`", "runs", "named right", "P", "95 %"] + [f"`{k}` error" for k in shown]
        )
        + " |",
        "|" + "---|" * (5 + len(shown)),
    ]
    for pt in cv["curve"]:
        errs = []
        for k in shown:
            e = pt["param_error"].get(k, {})
            errs.append(
                "-"
                if not e.get("n")
                else f"{_pct(e['median'])} [{_pct(e['p16'])}, {_pct(e['p84'])}]"
            )
        p = "-" if pt["p_named"] is None else f"{pt['p_named']:.2f}"
        lines.append(
            "| "
            + " | ".join(
                [
                    f"{pt['value']:g}",
                    str(pt["analysed"]),
                    str(pt["named_right"]),
                    p,
                    _ci(pt["p_named_ci95"]),
                    *errs,
                ]
            )
            + " |"
        )
    nl = cv["nulls"]
    rate = "-" if nl["rate"] is None else f"{nl['rate']:.2f}"
    named = ", ".join(f"{k} {v}" for k, v in nl["named"].items()) or "nothing named"
    lines += [
        "",
        f"False alarms on the null runs (no effect; significant, or an effect named): {nl['false_alarms']} "
        f"of {nl['analysed']} ({rate}, 95 % {_ci(nl['rate_ci95'])}; {nl['significant']} significant; "
        f"{named}).",
        "",
    ]
    return "\n".join(lines)


def plot_curves(cv: dict[str, Any], path: Path) -> Path:
    """P(named right) with its intervals and the false-alarm rate (top); the parameter errors
    (bottom), written to ``path`` (``curves.png``)."""
    from daq.plots import new_figure, save_figure  # matplotlib loads only when a plot is drawn

    meta = cv["campaign"]
    param = meta["grid"]["param"]
    fig, axes = new_figure(2, 1, figsize=(8.0, 7.0))
    top, bottom = axes[0, 0], axes[1, 0]
    xs = [pt["value"] for pt in cv["curve"]]
    have = [pt for pt in cv["curve"] if pt["p_named"] is not None]
    if have:
        x = [pt["value"] for pt in have]
        y = [pt["p_named"] for pt in have]
        lo = [pt["p_named"] - pt["p_named_ci95"][0] for pt in have]
        hi = [pt["p_named_ci95"][1] - pt["p_named"] for pt in have]
        top.errorbar(
            x, y, yerr=[lo, hi], fmt="o-", capsize=3, label=f"{meta['effect']} named (95 % Wilson)"
        )
    nl = cv["nulls"]
    if nl["rate"] is not None and xs:
        top.axhline(
            nl["rate"],
            color="C3",
            ls="--",
            label=f"false alarms on nulls: {nl['false_alarms']}/{nl['analysed']}",
        )
        top.axhspan(nl["rate_ci95"][0], nl["rate_ci95"][1], color="C3", alpha=0.12)
    top.set_ylim(-0.03, 1.03)
    top.set_ylabel("P(named right)")
    top.legend(loc="best", fontsize=8)
    top.set_title(
        f"{meta['effect']}: {meta.get('record', {}).get('duration_s', 0):g} s records, "
        f"{meta.get('seeds')} seed(s) per point",
        fontsize=10,
    )
    names = list(cv["curve"][0]["param_error"]) if cv["curve"] else []
    for i, k in enumerate(names):
        pts = [pt for pt in cv["curve"] if pt["param_error"][k]["n"]]
        if not pts:
            continue
        e = [pt["param_error"][k] for pt in pts]
        med = [100 * q["median"] for q in e]
        bottom.errorbar(
            [pt["value"] for pt in pts],
            med,
            yerr=[
                [m - 100 * q["p16"] for m, q in zip(med, e)],
                [100 * q["p84"] - m for m, q in zip(med, e)],
            ],
            fmt="os^vd"[i % 5],
            capsize=3,
            label=k,
        )
    bottom.axhline(0.0, color="0.5", lw=0.8)
    bottom.set_ylabel("fitted / true - 1 (%)\nmedian, 16-84 %")
    bottom.set_xlabel(param)
    if names:
        bottom.legend(loc="best", fontsize=8)
    for ax in (top, bottom):
        if meta["grid"].get("log"):
            ax.set_xscale("log")
        ax.grid(True, alpha=0.3)
    return save_figure(fig, path)
