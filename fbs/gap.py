"""``fbs gap FILE.h5 [--json] [--report DIR]``: the model-gap workflow (DESIGN.md sections 7-8).

``--json`` prints one object with DESIGN section 7's keys (``effect``, ``parameters``,
``significant``, ``gap_before_db``, ``gap_after_db``, ``candidates``, ``file``) plus
``uncertainties`` and ``effects`` (every effect named, in the order found). ``--report DIR``
writes ``model_before.h5``, ``model_after.h5``, the spectra plots, ``gap.md`` and
``refined.toml`` (the refined model as a sim config for ``fbs simulate --sim-config``); with
``--report`` the JSON adds ``refined_config``, that file's path (null if none was written). Like
every ``--json`` result it starts with what ran and on whose data (``analysis`` "gap", the
file's ``rig``, ``simulated``, this software, ``status``, ``verdict``: ``fbs.analyze.header``;
schema ``docs/schema/run-summary.schema.json``). The verdict is "pass" when the workflow ran to
its end - what it found is its result, not a limit - and "aborted" (exit 2) when interrupted,
the object then holding every key with nothing found. A file that cannot be analysed is an
error naming the problem (exit 2).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fbs import jsonout

if TYPE_CHECKING:
    from procedures.analysis.gap.workflow import GapResult


#: what ``--report DIR`` writes, none of it replaced without ``--force``
REPORT_FILES = ("model_before.h5", "model_after.h5", "refined.toml", "gap.md")


def _analyse(args: argparse.Namespace) -> GapResult:
    from procedures.analysis.gap.workflow import GapOptions, analyse

    opt = GapOptions(sim_config=args.sim_config, seed=args.seed)
    if args.report and not getattr(args, "force", False):
        held = [name for name in REPORT_FILES if (Path(args.report) / name).exists()]
        if held:
            raise FileExistsError(
                f"--report {args.report} already holds {', '.join(held)} (an earlier report): "
                f"give another folder, or --force to replace them"
            )
    return analyse(args.file, axis=args.axis, options=opt, report_dir=args.report)


def _refined_config(res: GapResult, report: str) -> str | None:
    from procedures.analysis.gap.report import refined_config_path

    path = refined_config_path(res, report)
    return str(path) if path is not None else None


def json_result(args: argparse.Namespace) -> dict[str, Any]:
    """The object ``--json`` prints (``fbs batch gap`` collects the same); with ``--report``
    also ``refined_config``, the path of the refined model's sim config (``DIR/refined.toml``)."""
    from fbs.analyze import header

    res = _analyse(args)
    out = header("gap", args.file, "pass") | res.to_json()
    if getattr(args, "report", None):
        out["refined_config"] = _refined_config(res, args.report)
    return out


#: an interrupted workflow's keys: nothing found, nothing explained
NOTHING_FOUND: dict[str, Any] = {
    "effect": None,
    "parameters": {},
    "uncertainties": {},
    "parameters_ci95": {},
    "significant": None,
    "gap_before_db": None,
    "gap_after_db": None,
    "candidates": [],
    "effects": [],
    "explained": None,
    "unexplained": [],
    "partial": [],
}


def _gap(args: argparse.Namespace) -> int:
    if args.json:
        from fbs.analyze import EXIT, header

        try:
            out = json_result(args)
        except KeyboardInterrupt:
            print(
                jsonout.dumps(
                    header("gap", args.file, "aborted", "aborted: interrupted")
                    | NOTHING_FOUND
                    | {"file": str(args.file)}
                )
            )
            print("fbs gap: interrupted", file=sys.stderr)
            return EXIT["aborted"]
        print(jsonout.dumps(out))
        return EXIT[out["verdict"]]
    res = _analyse(args)
    print(
        f"fbs gap {res.file}: axis {res.axis}, mode {res.mode}, {res.duration_s:.0f} s at {res.rate_hz:g} Hz, "
        f"channels {', '.join(res.channels)} ({res.elapsed_s:.1f} s)"
    )
    if not res.significant:
        print("  no significant departure from the nominal model: effect none")
    for i, f in enumerate(res.findings, 1):
        print(f"  {i}. {f.effect}: {f.parameter_text()} (95 % intervals in brackets)")
        print(
            f"     BIC score {f.score:.1f}, {f.margin:.1f} better than {f.runner_up}; closes "
            f"{f.gap_before_db:.2f} -> {f.gap_after_db:.2f} dB on its bands"
        )
    if res.unexplained:
        print("  explained: no - a significant departure remains that no catalogue effect closes:")
        for b in res.remaining[:8]:
            print(f"    {b.channel} {b.f_lo_hz:.3g}-{b.f_hi_hz:.3g} Hz, {b.deviation_db:+.1f} dB")
        for s in res.remaining_steps[:8]:
            print(
                f"    a step at {s.time_s:.1f} s ({s.size * 1e6:+.3g} urad) the model does not make"
            )
        for c in res.partial:
            closes = (
                f", closes {c['gap_closed_db']:.2f} of {c['of_db']:.2f} dB"
                if "gap_closed_db" in c
                else ""
            )
            closes += (
                f", fitted at its prior's bound: {'; '.join(c['at_bound'])}"
                if "at_bound" in c
                else ""
            )
            print(f"    best partial candidate: {c['effect']} (score {c['score']:.1f}{closes})")
    print(
        f"  gap {res.gap_before_db:.2f} dB before, {res.gap_after_db:.2f} dB after (models' expected spectra, "
        f"located bands)"
        + (
            f"; simulated runs {res.sim_gaps[0]:.2f} -> {res.sim_gaps[1]:.2f} dB"
            if res.sim_gaps
            else ""
        )
    )
    for b in res.located[:8]:
        print(
            f"  departs: {b.channel} {b.f_lo_hz:.3g}-{b.f_hi_hz:.3g} Hz, {b.deviation_db:+.1f} dB at {b.peak_hz:.4g} Hz"
        )
    if res.steps:
        print(
            f"  {len(res.steps)} offset step(s) in {res.step_channel}: "
            + ", ".join(f"{s.time_s:.1f} s ({s.size * 1e6:+.3g} urad)" for s in res.steps[:8])
        )
    for w in res.warnings:
        print(f"  warning: {w}")
    if args.report:
        refined = _refined_config(res, args.report)
        print(
            f"  wrote {args.report}/model_before.h5, model_after.h5, gap.md and plots"
            + (
                f"; the refined model as a sim config: {refined} (fbs simulate --sim-config {refined})"
                if refined
                else "; no refined sim config (see gap.md)"
            )
        )
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    g = sub.add_parser(
        "gap",
        help="model-gap workflow: where the measurement departs from the nominal model, "
        "and which catalogue effect closes the gap",
    )
    g.add_argument("file", metavar="FILE.h5", help="an fbs-run file (any writer)")
    g.add_argument(
        "--json",
        action="store_true",
        help="one JSON object on stdout: effect, parameters (with uncertainties "
        "and 95 %% intervals), significant, gap_before_db, gap_after_db, candidates, effects, explained, "
        "unexplained, file; with --report also refined_config, the path of DIR/refined.toml",
    )
    g.add_argument(
        "--report",
        metavar="DIR",
        help="write model_before.h5, model_after.h5, plots, gap.md and "
        "refined.toml (the refined model as a sim config for --sim-config) to DIR",
    )
    g.add_argument("--force", action="store_true", help="replace an earlier report in --report DIR")
    g.add_argument("--axis", help="platform axis X, Y or Z (default: the file's 'axis' attribute)")
    g.add_argument(
        "--sim-config",
        help="TOML sim config the nominal model starts from (default: the data sheet)",
    )
    g.add_argument("--seed", type=int, default=1, help="seed of the model simulations (default 1)")
    g.set_defaults(func=_gap, json_result=json_result)
