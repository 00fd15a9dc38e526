"""The detection curves' statistics (``procedures.analysis.gap.detection``): Wilson's interval
and the curves of synthetic run lines, with no campaign run (``tests/fbs/test_campaign.py`` runs
one and writes its table and plot)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from procedures.analysis.gap.detection import curves, run_key, wilson


@dataclass(frozen=True)
class Grid:
    param: str
    values: list[float]


def key(rec: dict) -> tuple:
    return run_key(rec["effect"], rec["params"], rec["seed"])


def _row(
    effect: str,
    params: dict,
    seed: int,
    named: list[str],
    fitted: dict | None = None,
    *,
    significant: bool | None = None,
    error: str | None = None,
) -> dict:
    """A run's line of runs.jsonl, as far as the curves read it."""
    return {
        "effect": effect,
        "params": params,
        "seed": seed,
        "named": named,
        "significant": bool(named) if significant is None else significant,
        "explained": True,
        "fitted": fitted or {},
        "error": error,
    }


# ---------------------------------------------------------------------------- units: Wilson's interval
@pytest.mark.parametrize(
    "k, n, lo, hi",
    [  # Wilson (1927); values as scipy's binomtest gives them
        (0, 10, 0.0, 0.27753),
        (10, 10, 0.72247, 1.0),
        (5, 10, 0.23659, 0.76341),
        (1, 2, 0.09453, 0.90547),
        (81, 263, 0.25529, 0.36621),
        (0, 1, 0.0, 0.79345),
    ],
)
def test_wilson_interval_known_values(k, n, lo, hi):
    got = wilson(k, n)
    assert got is not None
    assert got == pytest.approx((lo, hi), abs=6e-6)


@settings(max_examples=100, deadline=None)
@given(n=st.integers(1, 5000), data=st.data())
def test_wilson_interval_is_scipys(n, data):
    from scipy.stats import binomtest

    k = data.draw(st.integers(0, n))
    ci = binomtest(k, n).proportion_ci(0.95, method="wilson")
    assert wilson(k, n) == pytest.approx((ci.low, ci.high), abs=1e-9)


@settings(max_examples=200, deadline=None)
@given(n=st.integers(1, 10_000), data=st.data())
def test_wilson_interval_holds_the_estimate_and_narrows_with_n(n, data):
    k = data.draw(st.integers(0, n))
    lo, hi = wilson(k, n)
    assert 0.0 <= lo <= k / n <= hi <= 1.0
    lo4, hi4 = wilson(4 * k, 4 * n)
    assert hi4 - lo4 < hi - lo
    assert wilson(n - k, n) == pytest.approx(
        (1 - hi, 1 - lo), abs=1e-12
    )  # symmetric in k <-> n - k


def test_wilson_interval_of_nothing_is_none_and_of_impossible_counts_an_error():
    assert wilson(0, 0) is None
    with pytest.raises(ValueError):
        wilson(3, 2)


# ---------------------------------------------------------------------------- the curves
def test_curves_of_synthetic_runs():
    grid = Grid("amplitude_V", [0.001, 0.002])

    def params_at(v):
        return {"freq_hz": 200.0, "amplitude_V": v}

    lo, hi = params_at(0.001), params_at(0.002)
    rows = [
        # at 1 mV: seed 1 named right (+10 %), seed 2 named something else, seed 3 nothing, seed 4 an error
        _row("pickup_line", lo, 1, ["pickup_line"], {"amplitude_V": 0.0011, "freq_hz": 200.0}),
        _row(
            "pickup_line",
            lo,
            2,
            ["flicker_noise", "pickup_line"],
            {"amplitude_V": 0.005, "freq_hz": 200.0},
        ),
        _row("pickup_line", lo, 3, []),
        _row("pickup_line", lo, 4, [], error="its worker process died"),
        # at 2 mV: all four right, errors -2 %, 0, +2 %, +4 %
        *[
            _row(
                "pickup_line",
                hi,
                s,
                ["pickup_line"],
                {"amplitude_V": 0.002 * (1 + e), "freq_hz": 200.0},
            )
            for s, e in zip((1, 2, 3, 4), (-0.02, 0.0, 0.02, 0.04))
        ],
        # nulls: seed 1 significant with nothing named, seed 2 names an effect, seeds 3-4 quiet
        _row("none", {}, 1, [], significant=True),
        _row("none", {}, 2, ["time_delay"]),
        _row("none", {}, 3, []),
        _row("none", {}, 4, []),
    ]
    latest = {key(r): r for r in rows}
    cv = curves("pickup_line", grid, params_at, [1, 2, 3, 4], latest)
    assert cv["runs"] == 12 and cv["done"] == 12 and cv["errors"] == 1 and cv["complete"] is False
    p1, p2 = cv["curve"]
    assert (p1["analysed"], p1["named_right"], p1["errors"]) == (3, 1, 1)
    assert p1["p_named"] == pytest.approx(1 / 3) and p1["p_named_ci95"] == wilson(1, 3)
    assert p1["first_named"] == {"pickup_line": 1, "flicker_noise": 1, "none": 1}
    assert p1["param_error"]["amplitude_V"]["n"] == 1  # only the run named right
    assert p1["param_error"]["amplitude_V"]["median"] == pytest.approx(0.1)
    assert (p2["analysed"], p2["named_right"], p2["p_named"]) == (4, 4, 1.0)
    e = p2["param_error"]["amplitude_V"]
    assert e["median"] == pytest.approx(0.01) and e["n"] == 4
    assert e["p16"] == pytest.approx(np.percentile([-0.02, 0, 0.02, 0.04], 16))
    assert e["p84"] == pytest.approx(np.percentile([-0.02, 0, 0.02, 0.04], 84))
    assert p2["param_error"]["freq_hz"]["median"] == 0.0
    nl = cv["nulls"]
    assert (nl["analysed"], nl["false_alarms"], nl["significant"]) == (4, 2, 2)
    assert (
        nl["rate"] == 0.5 and nl["rate_ci95"] == wilson(2, 4) and nl["named"] == {"time_delay": 1}
    )

    # a run not done yet leaves the curve incomplete, not wrong
    del latest[key(rows[-1])]
    cv = curves("pickup_line", grid, params_at, [1, 2, 3, 4], latest)
    assert cv["done"] == 11 and cv["nulls"]["analysed"] == 3 and cv["nulls"]["false_alarms"] == 2


def test_curves_compare_a_derived_parameter_with_its_value_as_applied():
    """A bearing's eta follows from its stiffness and To: its error is against k / To^2, not the
    catalogue's default eta."""
    grid = Grid("stiffness_Nm_per_rad", [400.0])

    def params_at(v):
        return {"stiffness_Nm_per_rad": v, "To_Nm": 0.02, "eta_per_Nm": 1.6e6}

    p = params_at(400.0)
    fitted = {"stiffness_Nm_per_rad": 440.0, "To_Nm": 0.02, "eta_per_Nm": 440.0 / 0.02**2}
    latest = {key(r): r for r in [_row("bearing_friction", p, 1, ["bearing_friction"], fitted)]}
    cv = curves("bearing_friction", grid, params_at, [1], latest)
    err = cv["curve"][0]["param_error"]
    assert err["stiffness_Nm_per_rad"]["median"] == pytest.approx(0.1)
    assert err["eta_per_Nm"]["median"] == pytest.approx(0.1)
    assert err["To_Nm"]["median"] == pytest.approx(0.0)
