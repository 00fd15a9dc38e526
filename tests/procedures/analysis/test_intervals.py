"""Intervals through a scale factor (``through_scale``) and a prior's interval
(``prior_rel_half_width``): a figure read in urad through a measured K_g is only as good as K_g."""

from __future__ import annotations

import math

import numpy as np
import pytest

from procedures.analysis.intervals import Estimate, from_stderr, through_scale
from procedures.params import prior_rel_half_width


def test_a_figure_through_a_scale_covers_the_truth_the_scale_error_moves():
    """An rms read in volts to 0.2 % and divided by a K_g 0.4 % off, known to +-0.5 %: alone the
    interval misses the truth (the failure the coverage harness saw: 11 of 80 pickoff rms rows);
    through the scale's interval it covers it, and its half-width is the quadrature sum."""
    rng = np.random.default_rng(38)
    misses_alone = misses_through = 0
    for _ in range(400):
        truth, kg_err = 8.0, float(rng.normal(0.0, 0.005 / 1.96))
        read = truth * (1 + rng.normal(0.0, 0.002 / 1.96)) / (1 + kg_err)
        alone = from_stderr(read, read * 0.002 / 1.96)
        through = through_scale(alone, 0.005)
        assert through.resolved
        assert through.half_width == pytest.approx(math.hypot(alone.half_width, 0.005 * read))
        misses_alone += not alone.covers(truth)
        misses_through += not through.covers(truth)
    assert misses_alone > 0.3 * 400  # the scale's error dominates: 47 % miss
    assert misses_through < 0.08 * 400  # 95 % intervals: about 5 % miss


def test_through_scale_keeps_an_rms_non_negative_and_an_unresolved_figure_unresolved():
    est = Estimate(0.1, 0.0, 0.4, False, "too few blocks")
    got = through_scale(est, 0.5)
    assert not got.resolved and got.why == "too few blocks"
    assert got.lo == 0.0 and got.hi > 0.4
    assert through_scale(est, 0.0) is est
    nan = Estimate(float("nan"), float("nan"), float("nan"), False, "no data")
    assert through_scale(nan, 0.2) is nan


def test_a_priors_interval_gives_its_relative_half_width_or_none():
    prior = {
        "stopwatch": {
            "K_g_mV_per_urad": {"X": 6.5, "Y": 6.2},
            "K_g_mV_per_urad_ci95": {"X": [6.4, 6.55], "Y": None},
        }
    }
    # the larger side: (6.5 - 6.4) / 6.5
    assert prior_rel_half_width(prior, "stopwatch", "K_g_mV_per_urad", "X", 6.5) == pytest.approx(
        0.1 / 6.5
    )
    assert prior_rel_half_width(prior, "stopwatch", "K_g_mV_per_urad", "Y", 6.2) is None
    assert prior_rel_half_width(prior, "nominal", "K_g_mV_per_urad", "X", 6.5) is None
    assert prior_rel_half_width({}, "stopwatch", "K_g_mV_per_urad", "X", 6.5) is None
