"""Detection curves of the model-gap workflow (docs/gap.md section 6; ``fbs campaign gap``).

A campaign injects an effect at the values of a grid of one of its parameters, seed by seed, and
runs the workflow on each record; null runs (no effect, the same seeds) measure the false
alarms. This module turns the runs' result lines (``fbs.campaign_task.RUN_KEYS``) into the
curves: per grid value the share of the runs analysed that name the effect first, with its 95 %
Wilson score interval, and the parameter errors over the runs named right; over the null runs the
false-alarm rate and its interval. Pure statistics on the lines: how the runs are planned and
executed is the command line's (``fbs.campaign_plan``, ``fbs.campaign``), how the curves are
written the report's (``procedures.reports.detection_curves``).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from typing import Any, Protocol

#: the two-sided 95 % normal quantile
Z95 = 1.959963984540054


class GridLike(Protocol):
    """The grid a campaign runs over: its parameter and its values."""

    @property
    def param(self) -> str: ...

    @property
    def values(self) -> list[float]: ...


def run_key(effect: str, params: dict[str, float], seed: int) -> tuple[Any, ...]:
    """The key of one run (effect, its parameters, seed): a later line of it replaces an earlier."""
    return effect, tuple(sorted(params.items())), seed


def wilson(k: int, n: int, z: float = Z95) -> tuple[float, float] | None:
    """Wilson's score interval of a binomial proportion k / n (None for n = 0)."""
    if n <= 0:
        return None
    if not 0 <= k <= n:
        raise ValueError(f"wilson: {k} successes of {n} trials")
    p = k / n
    z2 = z * z
    centre = (p + z2 / (2 * n)) / (1 + z2 / n)
    half = z / (1 + z2 / n) * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n))
    # at k = 0 (k = n) the bound is 0 (1) exactly; the sum leaves a rounding error there
    return (0.0 if k == 0 else max(0.0, centre - half)), (
        1.0 if k == n else min(1.0, centre + half)
    )


def quantile(xs: list[float], q: float) -> float:
    """The q-quantile of sorted ``xs``, linearly interpolated (numpy's default)."""
    pos = q * (len(xs) - 1)
    i = int(math.floor(pos))
    j = min(i + 1, len(xs) - 1)
    return xs[i] + (xs[j] - xs[i]) * (pos - i)


def spread(xs: list[float]) -> dict[str, Any]:
    """How many, the median and the 16th and 84th percentiles (None of each when empty)."""
    xs = sorted(xs)
    if not xs:
        return {"n": 0, "median": None, "p16": None, "p84": None}
    return {
        "n": len(xs),
        "median": quantile(xs, 0.5),
        "p16": quantile(xs, 0.16),
        "p84": quantile(xs, 0.84),
    }


def truth(effect: str, params: dict[str, float]) -> dict[str, float]:
    """The parameters as applied (a bearing's eta follows from its stiffness and To)."""
    from simhw import effects

    e = effects.get(effect)
    return dict(e.derive(dict(params))) if e.derive else dict(params)


def curves(
    effect: str,
    grid: GridLike,
    params_at: Callable[[float], dict[str, float]],
    seeds: list[int],
    latest: dict[tuple[Any, ...], dict[str, Any]],
    meta: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Per grid value: ``p_named`` (the effect named first, of the runs analysed) with
    ``p_named_ci95`` (Wilson), ``first_named`` (what was named first, counted), and per parameter
    ``param_error`` (fitted / true - 1 over the runs named right: n, median, p16, p84); over the
    null runs the false-alarm rate (significant, or an effect named) with its interval."""
    points = []
    n_runs = n_done = n_err = 0
    for v in grid.values:
        params = params_at(v)
        applied = truth(effect, params)
        rows = [r for s in seeds if (r := latest.get(run_key(effect, params, s))) is not None]
        ok = [r for r in rows if r["error"] is None]
        right = [r for r in ok if r["named"][:1] == [effect]]
        errors: dict[str, dict[str, Any]] = {}
        for k, t in applied.items():
            rel = [
                r["fitted"][k] / t - 1
                for r in right
                if isinstance(r["fitted"].get(k), int | float) and t != 0
            ]
            errors[k] = spread(rel)
        n_runs, n_done, n_err = n_runs + len(seeds), n_done + len(rows), n_err + len(rows) - len(ok)
        points.append(
            {
                "value": v,
                "params": params,
                "runs": len(seeds),
                "done": len(rows),
                "errors": len(rows) - len(ok),
                "analysed": len(ok),
                "named_right": len(right),
                "named_right_explained": sum(1 for r in right if r["explained"]),
                "p_named": len(right) / len(ok) if ok else None,
                "p_named_ci95": wilson(len(right), len(ok)),
                "significant": sum(1 for r in ok if r["significant"]),
                "first_named": dict(
                    Counter(r["named"][0] if r["named"] else "none" for r in ok).most_common()
                ),
                "param_error": errors,
            }
        )
    rows = [r for s in seeds if (r := latest.get(run_key("none", {}, s))) is not None]
    ok = [r for r in rows if r["error"] is None]
    alarms = [r for r in ok if r["significant"] or r["named"]]
    n_runs, n_done, n_err = n_runs + len(seeds), n_done + len(rows), n_err + len(rows) - len(ok)
    nulls = {
        "runs": len(seeds),
        "done": len(rows),
        "errors": len(rows) - len(ok),
        "analysed": len(ok),
        "false_alarms": len(alarms),
        "rate": len(alarms) / len(ok) if ok else None,
        "rate_ci95": wilson(len(alarms), len(ok)),
        "significant": sum(1 for r in ok if r["significant"]),
        "named": dict(Counter(n for r in ok for n in r["named"]).most_common()),
    }
    return {
        "campaign": meta or {"effect": effect, "grid": {"param": grid.param}},
        "complete": n_done == n_runs and n_err == 0,
        "runs": n_runs,
        "done": n_done,
        "errors": n_err,
        "curve": points,
        "nulls": nulls,
    }
