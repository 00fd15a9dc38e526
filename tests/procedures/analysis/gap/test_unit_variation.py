"""Issue 17's acceptance A-D on data the workflow did not make, with what its model assumes varied.

Every file comes from ``independent.py`` (a transcription of DESIGN.md and the thesis that shares
no code with ``simhw``) with another unit's noise drawn over DESIGN.md section 8's nominal envelope
(white x0.6-1.6, 1/f corner 1.5-5 Hz with either knee form and slope 0.8-1.2, pickoff white
x0.5-2, lines +-1 Hz and x0.5-2, ADC ranges: ``independent.draw_nuisance``), over both axes; the hidden
effects are ``independent.draw_effect``'s and ``draw_outside``'s. The seeds are those of
``bench/gap_holdout.py``, which runs the full set (20 nominal seeds, 3 draws per effect) and
prints the table; this suite runs a subset of A and B and all of C and D:

* A: nominal, 10 seeds: at most one ``significant: true``.
* B: each catalogue effect the generator shows, 2 draws: named first in >= 90 %, the key
  parameter within 15 % in >= 85 %, its 95 % interval covering the truth in >= 85 %, the gap
  at least halved in >= 85 %.
* C: two effects of different kinds, 6 pairs x 2 draws: both named and no third in >= 80 %
  (issue 34's target), both key parameters within 20 % in >= 80 %.
* D: effects outside the catalogue, 8 files: ``explained: false`` in >= 80 %, a name with
  ``explained: true`` in none.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from procedures.analysis.gap.workflow import analyse

pytestmark = pytest.mark.slow


def _run(independent, folder, axis: str, seed: int, hidden: dict[str, Any]) -> dict[str, Any]:
    nuisance = independent.draw_nuisance(np.random.default_rng([17, seed]))
    path = independent.generate(
        folder / f"s{seed}.h5",
        axis=axis,
        seed=seed,
        duration_s=300.0,
        rate_hz=1000.0,
        **nuisance,
        **hidden,
    )
    try:
        return analyse(path).to_json()
    finally:
        path.unlink()


def _key(independent, j: dict[str, Any], effect: str) -> tuple[float, list[float] | None] | None:
    """The named effect's key parameter and its 95 % interval, if it was named."""
    key = independent.KEY_PARAM[effect]
    for e in j["effects"]:
        if e["effect"] == effect:
            return e["parameters"][key], e["parameters_ci95"].get(key)
    return None


@pytest.fixture(scope="module")
def runs(independent, tmp_path_factory):
    folder = tmp_path_factory.mktemp("unit_variation")
    out: dict[str, list[tuple[Any, ...]]] = {"A": [], "B": [], "C": [], "D": []}
    for i in range(10):
        out["A"].append((_run(independent, folder, "XY"[i % 2], 1000 + i, {}),))
    for e_idx, eff in enumerate(independent.HIDDEN_EFFECTS):
        for i in range(2):
            seed = 2000 + 10 * e_idx + i
            kw, truth = independent.draw_effect(eff, np.random.default_rng([18, seed]))
            out["B"].append(
                (eff, truth, _run(independent, folder, "XY"[(i + e_idx) % 2], seed, kw))
            )
    for p_idx, pair in enumerate(independent.HIDDEN_PAIRS):
        for i in range(2):
            seed = 3000 + 10 * p_idx + i
            rng = np.random.default_rng([19, seed])
            kw, truth = {}, {}
            for eff in pair:
                k, t = independent.draw_effect(eff, rng)
                kw.update(k)
                truth[eff] = t
            out["C"].append(
                (pair, truth, _run(independent, folder, "XY"[(i + p_idx) % 2], seed, kw))
            )
    plan = [
        ("dead_zone", "X"),
        ("dead_zone", "Y"),
        ("dead_zone", "X"),
        ("lead_zero", "Y"),
        ("lead_zero", "X"),
        ("lead_zero", "Y"),
        ("lead_pole", "X"),
        ("lead_pole", "Y"),
    ]
    for i, (kind, axis) in enumerate(plan):
        kw, _ = independent.draw_outside(kind, np.random.default_rng([20, 4000 + i]))
        out["D"].append((kind, _run(independent, folder, axis, 4000 + i, kw)))
    return out


def test_a_nominal_units_read_not_significant(runs):
    loud = [j for (j,) in runs["A"] if j["significant"]]
    assert len(loud) <= 1, [(j["effect"], j["unexplained"][:2]) for j in loud]


def test_b_single_effects_are_named_measured_and_covered(independent, runs):
    n = len(runs["B"])
    right = [j["effect"] == eff for eff, _, j in runs["B"]]
    assert sum(right) >= math.ceil(0.9 * n), [(eff, j["effect"]) for eff, _, j in runs["B"]]
    within, covered, with_interval, halved = 0, 0, 0, 0
    for eff, truth, j in runs["B"]:
        found = _key(independent, j, eff)
        if found is None:
            continue
        value, iv = found
        true = truth[independent.KEY_PARAM[eff]]
        within += abs(value - true) <= 0.15 * abs(true)
        if iv is not None:
            with_interval += 1
            covered += iv[0] <= true <= iv[1]
        halved += j["gap_after_db"] <= 0.5 * j["gap_before_db"]
    assert within >= math.ceil(0.85 * n)
    assert with_interval >= sum(right) - 1  # every named key parameter has its interval
    assert covered >= math.ceil(0.85 * with_interval), (covered, with_interval)
    assert halved >= math.ceil(0.85 * n)


def test_c_two_effects_both_named_and_no_third(independent, runs):
    n = len(runs["C"])
    clean = [sorted(e["effect"] for e in j["effects"]) == sorted(pair) for pair, _, j in runs["C"]]
    # Issue 34's target: 80 % (10 of 12). A Y time delay beside a 70.3 Hz pickup line inside the
    # pickoff pair's window, and a Y scale-factor error beside a floor-excited mount, are named
    # by neither alone (each leaves most of the gap where it acts): the pair search names them
    # together (measured 11 of 12 by bench/gap_holdout.py; one spurious 0.2 ms delay is left).
    assert sum(clean) >= math.ceil(0.8 * n), [
        (pair, [e["effect"] for e in j["effects"]]) for pair, _, j in runs["C"]
    ]
    close = 0
    for pair, truth, j in runs["C"]:
        ok = True
        for eff in pair:
            found = _key(independent, j, eff)
            true = truth[eff][independent.KEY_PARAM[eff]]
            ok &= found is not None and abs(found[0] - true) <= 0.2 * abs(true)
        close += ok
    assert close >= math.ceil(0.8 * n)


def test_d_effects_outside_the_catalogue_stay_unexplained(runs):
    n = len(runs["D"])
    honest = [not j["explained"] or not j["significant"] for _, j in runs["D"]]
    assert sum(honest) >= math.ceil(0.8 * n)
    forced = [(kind, j["effect"]) for kind, j in runs["D"] if j["explained"] and j["effects"]]
    assert not forced
    for _, j in runs["D"]:
        if not j["explained"]:
            assert j["unexplained"], "an unexplained departure lists its bands or steps"
