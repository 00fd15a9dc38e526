"""earth-rate and stopwatch: their numerics on synthetic data, and the procedures against sim
rigs whose values they must find by measurement (acceptance A, B)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import scipy.stats
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.rig import open_rig
from procedures.analysis.earth_rate import (
    DEFAULT_RUN_S,
    Station,
    fit_channel,
    mean_wander,
    platform_frame,
    run_span_s,
)
from procedures.analysis.stopwatch import (
    PARTNER_TRANSIENT_BOUND,
    ChannelRun,
    channel_result,
    partner_factors,
)
from procedures.analysis.stopwatch import crossing_interval as _crossing_interval
from procedures.analysis.stopwatch import restraint_fit as _restraint_fit
from procedures.analysis.stopwatch import smooth as _smooth
from procedures.calibrations.earth_rate import EarthRate
from procedures.calibrations.stopwatch import Stopwatch
from procedures.runner import run_procedure
from simhw.geometry import earth_rate_platform, platform_axes_enu, specific_force_platform

OMEGA = 7.292115e-5
LAT = 37.43


# ---------------------------------------------------------------------------- earth-rate numerics
def _station(
    tilt: float,
    spindle: float,
    psi0: float,
    gyros: dict[str, dict],
    pickoff: dict[str, float] | None = None,
    noise: dict[str, float] | None = None,
) -> dict:
    """A station's settled torquer means from simhw's own table geometry (independent of the fit):
    -K_TO V_T = Omega_i + d + g . f - sigma / (h/k)."""
    axes = platform_axes_enu(math.radians(tilt), math.radians(spindle), math.radians(psi0))
    w = earth_rate_platform(math.radians(LAT), OMEGA, axes)
    f = specific_force_platform(axes)
    v, pv = {}, {}
    for ch, g in gyros.items():
        w_i = w[{"X": 0, "XRD": 0, "Y": 1, "Z": 2}[ch]]
        sigma = (pickoff or {}).get(ch, 0.0)  # standing pickoff angle, rad
        rate = w_i + (g["d"] + g["g"] @ f) * 1e-6 - sigma / g.get("hk", 1.0)
        v[ch] = -rate / (g["kto"] * 1e-6) + (noise or {}).get(ch, 0.0)
        pv[ch] = sigma / 1e-6 * g.get("kg", 6.0) * 1e-3
    return Station(tilt=tilt, spindle=spindle, V=v, pickoff_V=pv)


def _positions(tilts=(0.0, 90.0, 45.0), n=8):
    return [
        (t, (p if i % 2 == 0 else (n - 1 - p)) * 360.0 / n)
        for i, t in enumerate(tilts)
        for p in range(n)
    ]


def test_the_frame_is_the_table_geometry():
    rng = np.random.default_rng(1)
    for _ in range(50):
        t, s, o = rng.uniform(0, 90), rng.uniform(0, 360), rng.uniform(-5, 5)
        w, f = platform_frame(t, s, o, LAT, OMEGA)
        axes = platform_axes_enu(math.radians(t), math.radians(s), math.radians(o))
        assert np.allclose(w, earth_rate_platform(math.radians(LAT), OMEGA, axes), atol=1e-18)
        assert np.allclose(f, specific_force_platform(axes))


@settings(max_examples=25, deadline=None)
@given(
    kto=st.floats(20, 50),
    drift=st.floats(-2, 2),
    psi0=st.floats(-3, 3),
    g=st.lists(st.floats(-0.3, 0.3), min_size=3, max_size=3),
    ch=st.sampled_from(["X", "Y", "Z", "XRD"]),
)
def test_the_multi_position_fit_recovers_scale_factor_and_every_drift(kto, drift, psi0, g, ch):
    gy = {ch: {"kto": kto, "d": drift, "g": np.array(g)}}
    stations = [_station(t, s, psi0, gy) for t, s in _positions()]
    f = fit_channel(
        ch,
        stations,
        latitude_deg=LAT,
        earth_rate_rad_per_s=OMEGA,
        offset_deg=None if ch != "Z" else psi0,
    )
    assert f.kto.value == pytest.approx(kto, rel=1e-7)
    assert f.drift.value == pytest.approx(drift, abs=1e-5)
    for a, v in zip("xyz", g):
        assert f.g_drift[a].value == pytest.approx(v, abs=1e-5)
    if ch != "Z":
        assert f.psi0_deg == pytest.approx(psi0, abs=1e-5)


def test_a_standing_pickoff_is_taken_out_of_the_scale_factor():
    """A proportional-only loop: the standing angle follows the torquer output, and its restraint
    share would read as K_TO (1 + 1/(G_p h/k)) without the term."""
    gp, hk, kto, kg = 0.5, 515.0, 32.0, 5.74  # G_p in 1/s: sigma = rate / G_p
    stations = []
    for t, s in _positions():
        clean = _station(t, s, 0.1, {"XRD": {"kto": kto, "d": 0.4, "g": np.zeros(3)}})
        rate = -clean.V["XRD"] * kto * 1e-6  # what the torquer would balance alone
        sigma = rate / (gp * hk + 1.0) * hk  # the float's share at equilibrium, rad
        stations.append(
            _station(
                t,
                s,
                0.1,
                {"XRD": {"kto": kto, "d": 0.4, "g": np.zeros(3), "hk": hk, "kg": kg}},
                pickoff={"XRD": sigma},
            )
        )
    with_term = fit_channel(
        "XRD",
        stations,
        latitude_deg=LAT,
        earth_rate_rad_per_s=OMEGA,
        restraint_s=hk,
        pickoff_mV_per_urad=kg,
    )
    without = fit_channel("XRD", stations, latitude_deg=LAT, earth_rate_rad_per_s=OMEGA)
    assert with_term.kto.value == pytest.approx(kto, rel=1e-7)
    assert without.kto.value / kto - 1 == pytest.approx(1 / (gp * hk), rel=0.05)
    assert with_term.restraint_correction == pytest.approx(-(without.kto.value / kto - 1), rel=0.05)


def test_what_the_design_cannot_vary_is_not_resolved():
    """At tilt 0 only, the specific force along every axis is fixed: no g-drift is reported."""
    gy = {"X": {"kto": 31.6, "d": 0.3, "g": np.array([0.0, 0.1, 0.05])}}
    stations = [_station(0.0, s, 0.0, gy) for s in np.arange(12) * 30.0]
    f = fit_channel("X", stations, latitude_deg=LAT, earth_rate_rad_per_s=OMEGA)
    assert f.kto.resolved and f.kto.value == pytest.approx(31.6, rel=1e-6)
    assert not any(e.resolved for e in f.g_drift.values())


def test_z_carries_the_table_offsets_uncertainty():
    """Issue 38 item 4: Z's input axis leans toward the base's north as the table tilts, so its
    earth rate goes as cos(o) of the base's azimuth offset, which Z takes from the horizontal
    channels: K_TO = -cos(o)/b_P. An offset 1 deg off (4 for 5 deg: K_TO +0.14 %) with a standard
    uncertainty of 1 deg is covered; the same without its uncertainty is not."""
    truth = {"kto": 34.1, "d": 0.3, "g": np.array([0.02, -0.03, 0.05])}
    stations = [_station(t, s, 5.0, {"Z": truth}) for t, s in _positions()]
    exact = fit_channel("Z", stations, latitude_deg=LAT, earth_rate_rad_per_s=OMEGA, offset_deg=4.0)
    assert exact.kto.value == pytest.approx(
        34.1 * math.cos(math.radians(4)) / math.cos(math.radians(5)), rel=1e-6
    )
    assert not exact.kto.covers(34.1)
    known = fit_channel(
        "Z",
        stations,
        latitude_deg=LAT,
        earth_rate_rad_per_s=OMEGA,
        offset_deg=4.0,
        offset_sd_deg=1.0,
    )
    assert known.kto.covers(34.1)
    assert known.kto.half_width == pytest.approx(
        math.hypot(
            exact.kto.half_width,
            scipy.stats.t.ppf(0.975, exact.dof)
            * 34.1
            * math.tan(math.radians(4))
            * math.radians(1.0),
        ),
        rel=0.01,
    )


def test_the_restraint_term_carries_a_units_pickoff_scale():
    """Issue 38 item 4: XRD's proportional caging leaves a standing pickoff angle whose restraint
    term (sigma / (h/k), sigma from the pickoff and the data sheet's K_g) moves K_TO by about
    -0.2 %. A unit whose K_g is x0.74 of the data sheet's makes that term 26 % small: K_TO then
    read +0.05 % outside an interval that took the term as good to 20 % (4 of 40 drawn rigs).
    The data sheet's K_g is now bounded by 20 % of its own, with h/k's 20 %."""
    hk, kg_true, kto = 515.0, 5.74 * 0.74, 32.0
    truth = {"kto": kto, "d": 0.4, "g": np.array([0.0, 0.0, 0.04]), "hk": hk, "kg": kg_true}
    stations = []
    for t, sp in _positions():
        w, _ = platform_frame(t, sp, 0.1, LAT, OMEGA)
        sigma = (w[0] + 0.4e-6) / 1.0  # the proportional loop's standing angle, 1 rad/s
        stations.append(_station(t, sp, 0.1, {"XRD": truth}, pickoff={"XRD": sigma}))
    f = fit_channel(
        "XRD",
        stations,
        latitude_deg=LAT,
        earth_rate_rad_per_s=OMEGA,
        restraint_s=hk,
        pickoff_mV_per_urad=5.74,
    )
    assert f.restraint_correction < -1e-3 and abs(f.kto.value / kto - 1) > 3e-4
    assert f.kto.covers(kto)
    # with the stopwatch's K_g (good to 0.3 %) the term is exact and the interval narrow again
    g = fit_channel(
        "XRD",
        stations,
        latitude_deg=LAT,
        earth_rate_rad_per_s=OMEGA,
        restraint_s=hk,
        pickoff_mV_per_urad=kg_true,
        pickoff_rel_uncertainty=0.003,
    )
    assert g.kto.covers(kto) and g.kto.half_width < f.kto.half_width


def _ar1(rho: float):
    def errors(rng: np.random.Generator, n: int) -> np.ndarray:
        e = np.zeros(n)
        for i in range(n):
            e[i] = (rho * e[i - 1] if i else 0.0) + rng.normal(0, 1e-3)
        return e

    return errors


def _flicker(rng: np.random.Generator, n: int, m: int = 16) -> np.ndarray:
    """1/f errors: white noise shaped by 1/sqrt(f) over n*m samples, averaged over each station's m."""
    X = np.fft.rfft(rng.normal(size=n * m))
    f = np.arange(len(X), dtype=float)
    f[0] = 1.0
    x = np.fft.irfft(X / np.sqrt(f), n * m).reshape(n, m).mean(axis=1)
    return 1e-3 * x / x.std()


COVERAGE_TRUTH = {"kto": 31.6, "d": 0.35, "g": np.array([0.05, 0.08, -0.04])}


def _coverage(errors, stations: list[Station], n: int = 200) -> dict[str, float]:
    """The share of ``n`` fits whose 95 % intervals cover each truth (``COVERAGE_TRUTH``, which
    ``stations`` hold exactly), ``errors(rng, k)`` added to the station means."""
    t = COVERAGE_TRUTH
    truth = {"K_TO": t["kto"], "drift": t["d"], **{f"g_{a}": g for a, g in zip("xyz", t["g"])}}
    rng = np.random.default_rng(7)
    hits = dict.fromkeys(truth, 0)
    for _ in range(n):
        e = errors(rng, len(stations))
        noisy = [dataclasses.replace(s, V={"X": s.V["X"] + ei}) for s, ei in zip(stations, e)]
        f = fit_channel("X", noisy, latitude_deg=LAT, earth_rate_rad_per_s=OMEGA)
        for k, v in truth.items():
            hits[k] += f.figures[k].covers(float(v))
    return {k: h / n for k, h in hits.items()}


@pytest.mark.parametrize(
    "errors", [_ar1(0.6), _ar1(0.9), _flicker], ids=["AR1-0.6", "AR1-0.9", "flicker"]
)
def test_intervals_cover_under_correlated_station_noise(errors):
    """Station errors that wander (AR(1), as a gyro's flicker drift does from one station to the
    next, or 1/f itself, which no AR(1) is): the 95 % intervals cover K_TO and the drifts at
    about their rate (measured: 0.89-0.95 at AR(1) rho 0.6 and 0.9, 0.93-0.985 on flicker).

    The fixed drift's interval also holds a run's mean wandering from the long-term mean below
    the run (``mean_wander``: flicker reaching a 12-day span); these errors have no such part,
    so its interval errs wide (0.98-1.0), and the test below holds it to its rate."""
    clean = [_station(t, s, 0.1, {"X": COVERAGE_TRUTH}) for t, s in _positions()]
    for k, c in _coverage(errors, clean).items():
        assert 0.87 <= c <= (1.0 if k == "drift" else 0.995), (k, c)


def _flicker_below_the_run(rng: np.random.Generator, n: int, m: int = 16, runs: int = 220):
    """One run's station errors cut at random from 1/f that goes on ``runs`` runs (about 1e6 s
    for 4430 s runs: ``DRIFT_SPAN_S``), zero mean over that span (the fixed drift's truth)."""
    N = n * m * runs
    X = np.fft.rfft(rng.normal(size=N))
    f = np.arange(len(X), dtype=float)
    X[0], f[0] = 0.0, 1.0
    x = np.fft.irfft(X / np.sqrt(f), N).reshape(-1, m).mean(axis=1)
    k = int(rng.integers(runs))
    return 1e-3 * x[k * n : (k + 1) * n] / x.std()


def test_the_fixed_drift_covers_its_long_term_mean_under_flicker():
    """A gyro's flicker drift goes on below any run: a run's mean drift is off the long-term
    mean by the flicker between the two spans, which the stations' own wander (the Allan floor)
    understates. With the stations' times (190 s apart, a 4430 s run) the fixed drift's interval
    carries it (``mean_wander``, 1.98 Allan floors): measured 0.965 of 200 runs, and K_TO and
    the g-drifts 0.93-0.965; with the Allan floor alone the drift covered 0.88 (issue 38: the
    horizontal fixed drifts of 40 drawn rigs, 111 of 120 with the floor alone, 115 with this)."""
    clean = [
        dataclasses.replace(
            _station(t, s, 0.1, {"X": COVERAGE_TRUTH}), t=(190.0 * i, 190.0 * i + 60)
        )
        for i, (t, s) in enumerate(_positions())
    ]
    assert run_span_s(clean) == 4430.0
    assert mean_wander(run_span_s(clean)) == pytest.approx(1.977, abs=1e-3)
    for k, c in _coverage(_flicker_below_the_run, clean).items():
        assert 0.9 <= c <= 0.995, (k, c)


def test_the_mean_wander_of_flicker():
    """sqrt(ln(S / T) / (2 ln 2)) Allan floors, never below one floor, and the span's guess when
    the stations do not say when they were averaged errs wide."""
    assert mean_wander(1e6 / 16) == pytest.approx(math.sqrt(4 * math.log(2) / (2 * math.log(2))))
    assert mean_wander(1e6) == mean_wander(2e6) == mean_wander(5e5) == 1.0
    plain = [_station(0.0, 0.0, 0.1, {"X": COVERAGE_TRUTH})] * 3
    assert run_span_s(plain) == DEFAULT_RUN_S and mean_wander(DEFAULT_RUN_S) > mean_wander(4430.0)


# ---------------------------------------------------------------------------- stopwatch numerics
def test_crossing_interval_of_an_exact_ramp():
    rate = 200.0
    t = np.arange(0, 30, 1 / rate)
    vg = -1.5 + 0.1 * t  # crosses -1 at 5 s and +1 at 25 s
    assert _crossing_interval(t, vg, -1.0, 1.0, +1, 1.0, rate) == pytest.approx(20.0, abs=1e-6)
    assert _crossing_interval(t, -vg, -1.0, 1.0, -1, 1.0, rate) == pytest.approx(20.0, abs=1e-6)


def test_smooth_is_a_centred_average():
    y = np.arange(10.0)
    assert _smooth(y, 3)[1:-1] == pytest.approx(y[1:-1])


def test_restraint_fit_recovers_slope_and_h_over_k():
    """Exact solution of V_g' = a (V_T - V_T0) - k (V_g - V_g0) + c under bias steps and holds."""
    rate, a, k, c = 200.0, 0.19, 1 / 500.0, 2e-4
    t = np.arange(0, 400, 1 / rate)
    vt = np.where(
        (t % 100) < 30, 0.3, np.where((t % 100) < 50, 0.0, np.where((t % 100) < 80, -0.3, 0.0))
    )
    vg = np.empty_like(t)
    vg[0] = 0.2
    for i in range(1, len(t)):  # exact per step for piecewise-constant input
        drive = (a * vt[i - 1] + c) / k + 0.2
        vg[i] = drive + (vg[i - 1] - drive) * math.exp(-k / rate)
    fit = _restraint_fit(t, vg, vt, vt_null=0.0, vg0=0.2, dt_s=0.5)
    assert fit["a"] == pytest.approx(a, rel=1e-3)
    assert fit["k"] == pytest.approx(k, rel=2e-2)
    assert fit["c"] == pytest.approx(c, rel=5e-2)  # 0.5 s means blur the bias steps a little


def _coupled_float(ka: float, kb: float, tau: float, rate: float = 20.0):
    """A two-degree-of-freedom float written from II C.4.d, not from the sim: channel a open loop
    under bias steps and holds, channel b caged by a PI loop (0.1 rad/s, zeta 0.7) on its pickoff;
    sigma_a' (1 + ka kb) = f_a + kb f_b, sigma_b' (1 + ka kb) = f_b - ka f_a, f = torquer rate
    - sigma / tau. Returns t, the pickoff of a (V, 6 mV/urad), its torquer (V, 30 urad/s/V) and b's."""
    kg, kto, wn, z = 6e-3 / 1e-6, 30e-6, 0.1, 0.7
    t = np.arange(0, 600, 1 / rate)
    phase = t % 150
    vt_a = np.where(phase < 40, 0.6, np.where(phase < 75, 0.0, np.where(phase < 115, -0.6, 0.0)))
    sa = sb = integ = 0.0
    ga, gb = np.empty_like(t), np.empty_like(t)
    for i in range(len(t)):
        vt_b = -(2 * z * wn * sb + wn * wn * integ) / kto
        gb[i] = vt_b
        fa, fb = kto * vt_a[i] - sa / tau, kto * vt_b - sb / tau
        da, db = (fa + kb * fb) / (1 + ka * kb), (fb - ka * fa) / (1 + ka * kb)
        ga[i] = sa * kg
        sa, sb, integ = sa + da / rate, sb + db / rate, integ + sb / rate
    return t, ga, vt_a, gb


def test_the_float_partners_loop_is_not_read_as_restraint():
    """With the partner's caging loop pushing the float through the viscous coupling, the fit
    without the partner's torquer misreads h/k; with it, h/k comes out as h/k (1 + ka kb)."""
    ka, kb, tau = 0.5, 0.05, 450.0
    t, vg, vt, vt_b = _coupled_float(ka, kb, tau)
    with_partner = _restraint_fit(t, vg, vt, vt_null=0.0, vg0=0.0, dt_s=0.5, partner=vt_b)
    without = _restraint_fit(t, vg, vt, vt_null=0.0, vg0=0.0, dt_s=0.5)
    assert 1 / with_partner["k"] == pytest.approx(tau * (1 + ka * kb), rel=0.02)
    assert abs(1 / without["k"] / tau - 1) > 0.05


def test_k_g_interval_carries_the_k_to_interval():
    r = ChannelRun(
        ch="X",
        kto=31.6,
        kto_from="earth-rate",
        dVg=2.0,
        null_slope=0.0,
        ramps=((-1, 20.0, -0.3), (1, 20.2, 0.3), (-1, 19.9, -0.3), (1, 20.1, 0.3)),
        fit={"a": 0.057, "a_se": 1e-4, "k": 1 / 400.0, "k_se": 8e-5, "dof": 9},
    )
    res = channel_result(r)
    alone, with_kto = res.kg_estimate(0.0), res.kg_estimate(0.01)
    assert alone.resolved and with_kto.resolved and alone.lo < res.kg < alone.hi
    # the K_TO's half-width in quadrature with the repetitions'; the partner transient's bound added
    bound = PARTNER_TRANSIENT_BOUND
    assert (res.kg - with_kto.lo) / res.kg - bound == pytest.approx(
        math.hypot((res.kg - alone.lo) / res.kg - bound, 0.01)
    )
    nominal = res.kg_estimate(None)
    assert not nominal.resolved and "nominal" in nominal.why
    # h/k: an interval around the fitted value, never a resolved figure (acceptance B: not reported)
    tau = res.tau_estimate()
    assert not tau.resolved and tau.lo < 400.0 < tau.hi


def test_h_over_k_takes_out_what_the_float_coupling_puts_in():
    """Issue 38 acceptance A (``bench/coverage_all.py``): the restraint fit's 1/k is
    h/k (1 + (c/h)_a (c/h)_b) (``test_the_float_partners_loop_is_not_read_as_restraint``); left
    in, the X-Y float's Y channel read h/k 2-3 % high and its bound missed on 3 of 18 drawn rigs.
    With the data sheet's h/c the value is divided by it, the bound spans h/c +-30 %."""
    h_c = {"X": 1.96, "Y": 21.0, "Z": 35.7, "XRD": 2.43}
    cc = 1 / (1.96 * 21.0)
    tau = 655.0
    r = ChannelRun(
        ch="Y",
        kto=33.4,
        kto_from="earth-rate",
        dVg=2.0,
        ramps=((-1, 20.0, -0.3), (1, 20.2, 0.3)),
        fit={"a": 0.057, "a_se": 1e-4, "k": 1 / (tau * (1 + cc)), "k_se": 4e-6, "dof": 9},
    )
    before = channel_result(r).tau_estimate()
    assert not before.lo <= tau <= before.hi  # what the coverage harness saw
    e = channel_result(r, h_c).tau_estimate()
    assert not e.resolved and e.lo <= tau <= e.hi and e.value == pytest.approx(tau)


def test_a_result_without_partner_factors_carries_the_transients_bound():
    """Issue 38 item 4: the float partner's caging transient moves every ramp the same way
    (II C.4.d), however well the repetitions agree. Readings of the noise-free thesis rig's Z
    channel made before the correction: -0.04 %, the repetitions within 0.004 %; their t interval
    alone (7.50688 [7.50627, 7.50748]) missed 7.51. A result without ``partner_factor`` (an older
    run) carries the transient's span as a bound on each side."""
    truth, kto, dvt, dvg = 7.51, 34.1, 0.6, 2.0
    dt = dvg / (truth * 1e-3 * kto * dvt)  # II C.1.a(6) at the true K_g
    bias = [-0.000320, -0.000577, -0.000228, -0.000553, -0.000255, -0.000635]
    r = ChannelRun(
        ch="Z",
        kto=kto,
        kto_from="given",
        dVg=dvg,
        null_slope=0.0,
        ramps=tuple(
            ((-1) ** (i + 1), dt / (1 + b), (-1) ** (i + 1) * dvt) for i, b in enumerate(bias)
        ),
        fit={"a": 0.26, "a_se": 1e-4, "k": 1 / 1072.0, "k_se": 1e-3, "dof": 9},
    )
    res = channel_result(r)
    e = res.kg_estimate(0.0)
    assert e.resolved and e.covers(truth) and e.value < truth
    assert e.hi - e.value == pytest.approx(e.value - e.lo)
    assert e.half_width > PARTNER_TRANSIENT_BOUND * e.value
    # with the factors (here: what each window ran slow by) the readings are corrected and the
    # interval is the statistical one plus the correction's own bound
    fixed = channel_result(
        dataclasses.replace(r, partner_factor=tuple(1 + b for b in bias))
    ).kg_estimate(0.0)
    assert fixed.value == pytest.approx(truth, rel=1e-9) and fixed.covers(truth)
    assert fixed.half_width < e.half_width


def test_partner_factor_is_the_coupled_floats_answer():
    """``partner_factors`` (II C.4.d): at the bias step the uncaged float turns at 1/(1 + (c/h)_a
    (c/h)_b) of its torquer's rate, the partner's loop not having answered yet; a window from rest
    to rest long after the step sees the whole torquer rate (the partner's integral caging gives
    back what it took); a 15 s ramp from rest runs slow (-0.66 %: the transient's first part)."""
    fs = 200.0
    t = np.arange(0, 400, 1 / fs)
    rate = np.where((t >= 10) & (t < 25), 20.0, 0.0)  # one 15 s ramp at 20 urad/s, then rest
    hc = dict(h_over_c=1.96, partner_h_over_c=21.0, partner_wn=0.1, partner_zeta=0.7)
    kk = 1 / (1.96 * 21.0)
    start, whole, ramp = partner_factors(t, rate, [(10.0, 10.5), (5.0, 399.0), (11.0, 24.0)], **hc)
    assert start == pytest.approx(1 / (1 + kk), rel=2e-3)
    assert whole == pytest.approx(1.0, abs=2e-4)
    assert 0.99 < ramp < 1.0
    # a proportional partner as fast as XRD's (1 rad/s) answers within a few seconds
    fast = partner_factors(
        t,
        rate,
        [(15.0, 24.0)],
        h_over_c=35.7,
        partner_h_over_c=2.43,
        partner_wn=1.0,
        partner_zeta=1.0,
        partner_proportional=True,
    )[0]
    assert abs(fast - 1) < 5e-4


def test_restraint_correction_is_x_coth_x():
    tau = 400.0
    r = ChannelRun(
        ch="X",
        kto=31.6,
        kto_from="given",
        dVg=2.0,
        null_slope=0.0,
        ramps=((-1, 20.0, -0.3), (1, 20.0, 0.3)),
        fit={"a": 0.057, "a_se": 1e-4, "k": 1 / tau, "k_se": 1e-5},
    )
    res = channel_result(r)
    naive = 2.0 / (20.0 * 0.3 * 31.6) * 1e3
    x = 20.0 / (2 * tau)
    assert res.naive[0] == pytest.approx(naive)
    assert res.kg == pytest.approx(naive * x / math.tanh(x))
    assert res.correction == pytest.approx(x / math.tanh(x) - 1)
    assert res.tau_s == pytest.approx(tau)


# ---------------------------------------------------------------------------- on the simulated rig
def _toml(values: dict) -> str:
    lines = []
    for section, kv in values.items():
        lines.append(f"[{section}]")
        lines += [f"{k} = {v!r}" for k, v in kv.items()]
    return "\n".join(lines) + "\n"


def _draw(seed: int) -> dict:
    """A sim rig with other torquer and pickoff scale factors, drifts and table offset."""
    rng = np.random.default_rng(seed)
    cfg = {"table": {"base_azimuth_offset_deg": float(rng.uniform(-1.0, 1.0))}}
    for ch, kto, kg in (
        ("X", 31.6, 6.03),
        ("Y", 33.4, 6.70),
        ("Z", 34.1, 7.51),
        ("XRD", 32.0, 5.74),
    ):
        cfg[f"gyro.{ch}"] = {
            "torquer_scale_urad_per_s_per_V": float(kto * rng.uniform(0.88, 1.12)),
            "pickoff_scale_mV_per_urad": float(kg * rng.uniform(0.85, 1.15)),
            "fixed_drift_urad_per_s": float(rng.uniform(-0.8, 0.8)),
        }
    return cfg


@pytest.mark.slow
@pytest.mark.parametrize("seed", [11, 23])
def test_earth_rate_and_stopwatch_find_a_random_rig(tmp_path, seed):
    """Acceptance B: K_TO within 0.5 %, K_g within 2 % of values the procedures were never told."""
    cfg = _draw(seed)
    path = tmp_path / "rig.toml"
    path.write_text(_toml(cfg))
    with open_rig(f"sim?warm=1&seed={seed}&watchdog=5&config={path}") as rig:
        er = run_procedure(EarthRate(), rig, tmp_path)
        assert er.verdict == "pass", er.error or [m for m in er.measurements if m.passed is False]
        sw = run_procedure(Stopwatch(prior={"earth-rate": er.values}), rig, tmp_path)
        assert sw.verdict == "pass", sw.error or [m for m in sw.measurements if m.passed is False]
    for ch in ("X", "Y", "Z", "XRD"):
        g = cfg[f"gyro.{ch}"]
        assert er.values["K_TO_urad_per_s_per_V"][ch] == pytest.approx(
            g["torquer_scale_urad_per_s_per_V"], rel=5e-3
        )
        assert sw.values["K_g_mV_per_urad"][ch] == pytest.approx(
            g["pickoff_scale_mV_per_urad"], rel=2e-2
        )
    # the table's azimuth offset is found too (X, Y, XRD each see it)
    psi0 = [m.value for m in er.measurements if m.name.startswith("table azimuth misalignment")]
    assert np.allclose(psi0, cfg["table"]["base_azimuth_offset_deg"], atol=0.15)


#: the gyros' random drift and every noise off: what is left is the method's own error
_QUIET = {
    **{
        f"gyro.{ch}": {
            "arw_urad_per_sqrt_s": 0.0,
            "bias_instability_urad_per_s": 0.0,
            "rrw_urad_per_s_per_sqrt_s": 0.0,
            "pickoff_noise_rms_urad": 0.0,
        }
        for ch in ("X", "Y", "Z", "XRD")
    },
    "autocollimator.X": {"nea_urad": 0.0},
    "autocollimator.Y": {"nea_urad": 0.0},
    "azimuth": {"nea_urad": 0.0},
}


@pytest.mark.slow
def test_stopwatch_takes_the_float_partners_transient_out(tmp_path):
    """Issue 38 item 4: on a noise-free rig whose X pickoff is 5.03 mV/urad (x0.83 of the data
    sheet's: a 400 urad ramp) the stopwatch read K_g +0.16 % high, outside its own interval
    5.039 [5.03381, 5.05427]: the partner's (Y's) caging loop overshoots while X ramps (II
    C.4.d). With the transient modelled per window it reads within 0.05 % (measured +0.036 %),
    inside its interval."""
    cfg = {k: dict(v) for k, v in _QUIET.items()}
    cfg["gyro.X"].update(pickoff_scale_mV_per_urad=5.03, pickoff_lines=[])
    for ch in ("Y", "Z", "XRD"):
        cfg[f"gyro.{ch}"]["pickoff_lines"] = []
    path = tmp_path / "rig.toml"
    path.write_text(_toml(cfg))
    with open_rig(f"sim?warm=1&seed=1&watchdog=5&config={path}") as rig:
        sw = run_procedure(
            Stopwatch(Stopwatch.Params(channels=["X"], kto_urad_per_s_per_V={"X": 31.6})),
            rig,
            tmp_path,
        )
    assert sw.verdict == "pass", sw.error
    kg, (lo, hi) = sw.values["K_g_mV_per_urad"]["X"], sw.values["K_g_mV_per_urad_ci95"]["X"]
    assert kg == pytest.approx(5.03, rel=5e-4)
    assert lo <= 5.03 <= hi


@pytest.mark.slow
def test_the_most_repetitions_allowed_fit_a_channels_result_in_its_event(tmp_path):
    """A channel's step result is one 1 KiB event of the run file. With the float partner's
    factors and 15-digit fit figures a 3-repetition XRD channel made 1,030 bytes and the run
    aborted at the channel's end (a fresh-clone suite, 2026-11-29); figures are now kept to 7
    significant digits and repetitions limited to what fits: the most allowed, on a noisy rig."""
    most = 4
    with pytest.raises(ValueError, match="repetitions"):
        Stopwatch.Params(repetitions=most + 1)
    with open_rig("sim?warm=1&seed=7&watchdog=5") as rig:
        sw = run_procedure(
            Stopwatch(
                Stopwatch.Params(
                    channels=["XRD"], repetitions=most, kto_urad_per_s_per_V={"XRD": 32.0}
                )
            ),
            rig,
            tmp_path,
        )
    assert sw.verdict == "pass", sw.error
    assert sw.values["K_g_mV_per_urad"]["XRD"] == pytest.approx(5.74, rel=0.02)


@pytest.mark.slow
def test_the_multi_position_test_separates_fixed_and_g_sensitive_drift(tmp_path):
    """Acceptance C (issue 18): fixed drifts of 0.5 urad/s and g-sensitive drifts of 0.1 urad/s/g
    on a rig the procedure is never told about: each separated, resolved where the design can
    (the horizontal channels), every interval covering its truth; Z's fixed drift unresolved."""
    gyro = {
        "X": {"fixed_drift_urad_per_s": 0.5, "g_drift_x_urad_per_s_per_g": 0.1},
        "Y": {"fixed_drift_urad_per_s": -0.5, "g_drift_y_urad_per_s_per_g": 0.1},
        "Z": {"fixed_drift_urad_per_s": 0.5, "g_drift_x_urad_per_s_per_g": 0.1},
        "XRD": {"fixed_drift_urad_per_s": 0.5, "g_drift_z_urad_per_s_per_g": 0.1},
    }
    cfg = {
        f"gyro.{ch}": {
            "fixed_drift_urad_per_s": 0.0,
            **{f"g_drift_{a}_urad_per_s_per_g": 0.0 for a in "xyz"},
            **v,
        }
        for ch, v in gyro.items()
    }
    path = tmp_path / "rig.toml"
    path.write_text(_toml(cfg))
    with open_rig(f"sim?warm=1&seed=5&watchdog=5&config={path}") as rig:
        er = run_procedure(EarthRate(), rig, tmp_path)
    assert er.verdict == "pass", er.error
    v = er.values
    for ch in ("X", "Y", "Z", "XRD"):
        for key, cfg_key in (
            ("drift_urad_per_s", "fixed_drift_urad_per_s"),
            *((f"g_drift_{a}_urad_per_s_per_g", f"g_drift_{a}_urad_per_s_per_g") for a in "xyz"),
        ):
            lo, hi = v[f"{key}_ci95"][ch]
            assert lo <= cfg[f"gyro.{ch}"][cfg_key] <= hi, (ch, key, lo, hi)
    assert v["resolved"]["drift_urad_per_s"] == {"X": True, "Y": True, "Z": False, "XRD": True}
    assert (
        v["resolved"]["g_drift_x_urad_per_s_per_g"]["X"]
        and v["resolved"]["g_drift_y_urad_per_s_per_g"]["Y"]
    )
    assert v["drift_urad_per_s"]["Z"] is None and v["K_TO_urad_per_s_per_V"]["Z"] is not None
