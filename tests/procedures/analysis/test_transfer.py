"""``procedures.analysis.transfer`` on data made without ``simhw``: the closed loop of eqs.
3.21-3.28 solved exactly in the frequency domain (circular, one FFT over the whole record),
with the network's corners, the inertia, damping and stiffness drawn (issue 22, acceptance A:
the network within 1 dB and 5 deg over 0.3-50 Hz, the inertia within 5 %, the stiffness within
10 %, each interval covering the truth).

The generator is a separate transcription: the plant as a transfer function, not the
simulator's state space; noise synthesized by FFT with a 1/f part and a white part; the
excitation a periodic multisine written out sample by sample as a ZOH at the update rate.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from daq.runfile import RunWriter
from drivers.rig_datasheet import AutocollimatorConstants, PlatformConstants
from procedures.analysis import transfer
from procedures.analysis.transfer import (
    DESIGN_NETWORK,
    NETWORK_CORNERS,
    SEARCH_FACTOR,
    TransferError,
    _log_residual,
    _log_residual_jacobian,
    _network_params,
    block_csd,
    file_blocks,
    fit_network,
    fit_platform,
    jackknife_se,
    network_response,
    periodic_blocks,
    response,
)

FS = 1000.0
URAD = 1e-6


def _network(f, p):
    """eq. 3.28 written again here (not imported), inverted."""
    s = 2j * np.pi * f
    w = [p[f"w{i}_rad_per_s"] for i in range(1, 7)]
    return (
        -p["gain"]
        * (s / w[1] + 1)
        * (s / w[2] + 1)
        / ((s / w[0] + 1) * (s / w[3] + 1) * (s / w[4] + 1) * (s / w[5] + 1))
    )


def _colored(rng, n, white, corner_hz=2.0):
    """Real noise of n samples: white density ``white`` (V^2/Hz one-sided) plus 1/f below ``corner_hz``."""
    f = np.fft.rfftfreq(n, 1 / FS)
    f[0] = f[1]
    amp = np.sqrt(white * (1 + corner_hz / f) * FS * n / 2)
    spec = amp * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)) / math.sqrt(2)
    spec[0] = 0
    return np.fft.irfft(spec, n)


def _write(path: Path, data: dict[str, np.ndarray]) -> Path:
    with RunWriter(
        path, rig="test-generator", mode=3, rate_hz=FS, channels=dict.fromkeys(data, "V")
    ) as w:
        w.append(data)
    return path


def _quantize(x, range_V, bits=16):
    q = 2 * range_V / 2**bits
    return np.clip(np.round(x / q) * q, -range_V, range_V - q)


# ---------------------------------------------------------------------------- the network
def draw_network(rng):
    return {
        "gain": float(rng.uniform(0.5, 2.0)),
        "w1_rad_per_s": float(rng.uniform(0.08, 0.3)),
        "w2_rad_per_s": float(rng.uniform(6, 16)),
        "w3_rad_per_s": float(rng.uniform(20, 50)),
        "w4_rad_per_s": float(rng.uniform(120, 320)),
        "w5_rad_per_s": float(rng.uniform(800, 1800)),
        "w6_rad_per_s": float(rng.uniform(3000, 8000)),
    }


def network_file(tmp_path, rng, p, seconds=160.0):
    n = int(seconds * FS)
    ac = _colored(rng, n, (3e-3) ** 2 / 100, corner_hz=3.0)  # ~3 mV rms control channel
    f = np.fft.rfftfreq(n, 1 / FS)
    pa = np.fft.irfft(np.fft.rfft(ac) * _network(f, p), n)
    pa += _colored(rng, n, (2e-6) ** 2)  # electronic noise after the network
    return _write(
        tmp_path / "net.h5", {"ac_x_ctl": _quantize(ac, 1.0), "pa_x": _quantize(pa, 0.05)}
    )


def drawn_network_fit(tmp_path, seed, lo_hz, hi_hz):
    """A drawn network (``draw_network``) recorded and fitted over ``lo_hz``..``hi_hz``."""
    rng = np.random.default_rng(seed)
    p = draw_network(rng)
    path = network_file(tmp_path, rng, p)
    resp = response(file_blocks(path, ["ac_x_ctl", "pa_x"], 8.0), "ac_x_ctl", "pa_x")
    return p, fit_network(resp, lo_hz, hi_hz)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_network_fit_matches_a_drawn_network_within_1_db_and_5_deg(tmp_path, seed):
    p, fit = drawn_network_fit(tmp_path, seed, 0.5, 100.0)
    f = np.geomspace(0.3, 50, 300)
    d = fit.curve(f) / _network(f, p)
    assert np.max(np.abs(20 * np.log10(np.abs(d)))) < 1.0, p
    assert np.max(np.abs(np.degrees(np.angle(d)))) < 5.0, p
    # the corners the band resolves: every resolved interval covers its truth
    for k in ("w2_rad_per_s", "w3_rad_per_s", "w4_rad_per_s"):
        e = fit.estimates[k]
        assert e.lo / 1.02 <= p[k] <= e.hi * 1.02, (k, e, p[k])
    # below the band the gain and the lowest pole are one figure: never reported as resolved apart
    assert not fit.estimates["gain"].resolved
    assert fit.residual_normalized < 3


def test_a_network_fit_stopped_at_its_evaluation_limit_resolves_nothing(tmp_path, monkeypatch):
    """A least-squares fit that ends at its evaluation limit (status 0) sits where it stopped:
    its figures are unresolved with the reason, and the fit says so in its notes."""
    rng = np.random.default_rng(2)
    path = network_file(tmp_path, rng, draw_network(rng))
    resp = response(file_blocks(path, ["ac_x_ctl", "pa_x"], 8.0), "ac_x_ctl", "pa_x")
    converged = fit_network(resp, 0.5, 100.0)
    assert any(e.resolved for e in converged.estimates.values())
    assert "notes" not in converged.values()
    monkeypatch.setattr(transfer, "NETWORK_MAX_EVALUATIONS", 2)
    stopped = fit_network(resp, 0.5, 100.0)
    assert not any(e.resolved for e in stopped.estimates.values())
    why = stopped.values()["why_unresolved"]
    was = [k for k, e in converged.estimates.items() if e.resolved]
    assert all("evaluations, unconverged" in why[k] for k in was), why
    assert any("limit of 2 evaluations" in n for n in stopped.values()["notes"])


def test_a_start_pinned_at_its_search_edge_does_not_move_the_search(tmp_path):
    """The fit inside the excited loop starts from the quiet record's, whose w1 (below the band)
    may sit at the edge of its own search, design / 20. The search stays about the design, so
    the interval of a w1 the band cannot see still holds it (a search about the start ended at
    0.150 for a true 0.154 on drawn rigs)."""
    rng = np.random.default_rng(5)
    p = draw_network(rng) | {"w1_rad_per_s": 0.16}
    path = network_file(tmp_path, rng, p)
    resp = response(file_blocks(path, ["ac_x_ctl", "pa_x"], 8.0), "ac_x_ctl", "pa_x")
    pinned = dict(DESIGN_NETWORK) | {"w1_rad_per_s": DESIGN_NETWORK["w1_rad_per_s"] / 20}
    pinned["gain"] = p["gain"] * p["w1_rad_per_s"] / pinned["w1_rad_per_s"]
    fit = fit_network(resp, 3.0, 100.0, start=pinned)
    e = fit.estimates["w1_rad_per_s"]
    assert not e.resolved
    assert e.lo <= p["w1_rad_per_s"] <= e.hi, e


def test_h1_intervals_cover_the_truth_in_most_bins(tmp_path):
    rng = np.random.default_rng(7)
    p = dict(DESIGN_NETWORK)
    path = network_file(tmp_path, rng, p)
    resp = response(file_blocks(path, ["ac_x_ctl", "pa_x"], 8.0), "ac_x_ctl", "pa_x")
    sel = (resp.f > 0.5) & (resp.f < 100)
    truth = network_response(resp.f[sel], p)
    lo, hi = resp.gain_db_ci()
    g = 20 * np.log10(np.abs(truth))
    covered = np.mean((lo[sel] <= g) & (g <= hi[sel]))
    assert covered > 0.88, covered  # 95 % intervals from 7 degrees of freedom: about 0.95


def test_response_refuses_one_channel_twice_and_unknown_channels(tmp_path):
    rng = np.random.default_rng(3)
    path = network_file(tmp_path, rng, dict(DESIGN_NETWORK), seconds=80.0)
    b = file_blocks(path, ["ac_x_ctl", "pa_x"], 8.0)
    with pytest.raises(TransferError, match="different channels"):
        response(b, "pa_x", "pa_x")
    with pytest.raises(TransferError, match="gyro_x"):
        response(b, "gyro_x", "pa_x")
    with pytest.raises(TransferError, match="fewer than 8 blocks"):
        file_blocks(path, ["ac_x_ctl", "pa_x"], 16.0)


# ---------------------------------------------------------------------------- the platform
PC = PlatformConstants(
    0.70, 1.02, 302.0, 0.53, 0.53, 23.0, armature_H=0.023, command_divider=0.0075
)
AC = AutocollimatorConstants(5.70, 5.63)


def _plant(f, J, D, k, pc=PC, ac=AC):
    """theta per amplifier-input volt, then the instrumentation channel's filters and scale."""
    s = 2j * np.pi * f
    # a damping or a stiffness that depends on frequency
    D = D(2 * np.pi * np.asarray(f, float)) if callable(D) else D
    k = k(2 * np.pi * np.asarray(f, float)) if callable(k) else k
    motor = (
        pc.amp_gain
        * pc.motor_Nm_per_A
        / (
            (pc.armature_H * s + pc.armature_ohm) * (J * s * s + D * s + k)
            + pc.motor_Nm_per_A * pc.back_emf_V_s * s
        )
    )
    w1, w2, z2 = ac.inst_filter1_rad_per_s, ac.inst_filter2_rad_per_s, ac.inst_filter2_zeta
    filt = w1 / (s + w1) * w2 * w2 / (s * s + 2 * z2 * w2 * s + w2 * w2)
    return motor * filt * ac.inst_mV_per_urad * 1e-3 / URAD


def platform_file(
    tmp_path, rng, J, D, k, *, period_s=16.0, periods=12, level_V=0.2, update_hz=250.0
):
    n = int(period_s * periods * FS)
    per = int(period_s * update_hz)
    spec = np.zeros(per // 2 + 1, complex)
    fl = np.fft.rfftfreq(per, 1 / update_hz)
    band = (fl >= 0.1) & (fl <= 60)
    spec[band] = np.exp(2j * np.pi * rng.random(band.sum()))
    one = np.fft.irfft(spec, per)
    one *= level_V / one.std()
    r = np.repeat(np.tile(one, periods), int(FS / update_hz))  # the DAC's ZOH
    f = np.fft.rfftfreq(n, 1 / FS)
    G = _plant(f, J, D, k)  # pa -> ac_inst (V/V)
    Gctl = G  # the control path: same plant
    C = _network(f, DESIGN_NETWORK)
    nac = _colored(rng, n, (0.45 * URAD * 5.7e-3 / URAD) ** 2 / 100, corner_hz=3.0)
    R, N = np.fft.rfft(r), np.fft.rfft(nac)
    PA = (PC.command_divider * R + C * N) / (1 - C * Gctl)  # pa = Kd r + C (ac + n); C is inverted
    AC_ = G * PA + N
    pa = np.fft.irfft(PA, n) + _colored(rng, n, (1e-6) ** 2)
    ac = np.fft.irfft(AC_, n)
    return _write(
        tmp_path / "plat.h5",
        {"cmd_x": _quantize(r, 10.0), "pa_x": _quantize(pa, 0.05), "ac_x_inst": _quantize(ac, 1.0)},
    )


@pytest.mark.parametrize("seed", [11, 12, 13, 14])
def test_platform_fit_recovers_drawn_inertia_and_stiffness_with_covering_intervals(tmp_path, seed):
    rng = np.random.default_rng(seed)
    J, D, k = (
        float(rng.uniform(0.3, 1.2)),
        float(rng.uniform(0.4, 2.0)),
        float(rng.uniform(150, 900)),
    )
    path = platform_file(tmp_path, rng, J, D, k)
    b = periodic_blocks([(path, 0, 10**9)], ["cmd_x", "pa_x", "ac_x_inst"], 16.0)
    fit = fit_platform(response(b, "pa_x", "ac_x_inst", via="cmd_x"), PC, AC, 0.2, 50.0)
    ej, ek, ed = (
        fit.estimates[n] for n in ("inertia_kg_m2", "stiffness_Nm_per_rad", "damping_Nms")
    )
    assert abs(ej.value / J - 1) < 0.05 and ej.covers(J), (ej, J)
    assert abs(ek.value / k - 1) < 0.10 and ek.covers(k), (ek, k)
    assert ed.covers(D), (ed, D)
    assert ej.resolved and ek.resolved


def test_a_damping_that_depends_on_frequency_is_not_resolved_and_a_viscous_one_is(tmp_path):
    """Issue 38 item 2: a bearing with hysteresis (Dahl, eq. 5.2) loses energy per cycle, so its
    equivalent damping goes as 1 / w: the platform fit's D is then no constant, and was printed
    resolved (2.41 [2.20, 2.62] against the gimbals' 1.17). Here the independent generator's
    plant has D(w) = 1.0 + h / w (h 60 N m/rad, about what the thesis rig's bearing showed at
    2 urad rms): D is unresolved, says why, and its interval holds D at the resonance; the same
    generator with a viscous D keeps it resolved and covering."""
    J, k, D0, h = 0.7, 400.0, 1.0, 60.0
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    path = platform_file(
        tmp_path / "a", np.random.default_rng(31), J, lambda w: D0 + h / np.maximum(w, 1e-9), k
    )
    b = periodic_blocks([(path, 0, 10**9)], ["cmd_x", "pa_x", "ac_x_inst"], 16.0)
    fit = fit_platform(response(b, "pa_x", "ac_x_inst", via="cmd_x"), PC, AC, 0.5, 50.0)
    ed = fit.estimates["damping_Nms"]
    assert not ed.resolved and "depends on frequency" in ed.why, ed
    assert ed.covers(D0 + h / math.sqrt(k / J)), ed
    assert fit.local_damping is not None and fit.local_damping.frequency_dependent()
    path = platform_file(tmp_path / "b", np.random.default_rng(32), J, D0 + h / math.sqrt(k / J), k)
    b = periodic_blocks([(path, 0, 10**9)], ["cmd_x", "pa_x", "ac_x_inst"], 16.0)
    fit = fit_platform(response(b, "pa_x", "ac_x_inst", via="cmd_x"), PC, AC, 0.5, 50.0)
    ed = fit.estimates["damping_Nms"]
    assert ed.resolved and ed.covers(D0 + h / math.sqrt(k / J)), ed
    assert fit.local_damping is not None and not fit.local_damping.frequency_dependent()


def test_a_bearing_whose_stiffness_rises_with_frequency_leaves_the_inertia_covered(tmp_path):
    """Issue 38 acceptance A (``bench/coverage_all.py``): on drawn rigs with Dahl bearings the
    Mode-4 inertia read 4.5-5.3 % low with +-2.7-4.2 % intervals (4 of 11 missed). Such a
    bearing's stiffness rises from the large slow motion to the small fast one; here the
    independent generator's bearing has k(w) rising from 600 to 1100 N m/rad about 3 Hz (what
    the drawn Dahl rig's record showed) and a hysteretic damping D(w) = 1 + 60 / w: one constant
    k read J several % low; the interval now also holds the fit with a stiffness growing as ln f.
    """
    J = 0.9

    def k(w):
        return 600.0 + 500.0 * (w / 20.0) ** 2 / (1 + (w / 20.0) ** 2)

    path = platform_file(
        tmp_path, np.random.default_rng(41), J, lambda w: 1 + 60 / np.maximum(w, 1e-9), k
    )
    b = periodic_blocks([(path, 0, 10**9)], ["cmd_x", "pa_x", "ac_x_inst"], 16.0)
    fit = fit_platform(response(b, "pa_x", "ac_x_inst", via="cmd_x"), PC, AC, 0.5, 50.0)
    ej = fit.estimates["inertia_kg_m2"]
    assert ej.covers(J), ej
    assert abs(ej.value / J - 1) > 0.01  # the one-k fit is biased: what the interval must hold
    assert any("ln f" in n for n in fit.notes), fit.notes


def test_platform_fit_does_not_use_the_data_sheet_inertia(tmp_path):
    rng = np.random.default_rng(21)
    path = platform_file(tmp_path, rng, 0.55, 1.0, 400.0)
    b = periodic_blocks([(path, 0, 10**9)], ["cmd_x", "pa_x", "ac_x_inst"], 16.0)
    resp = response(b, "pa_x", "ac_x_inst", via="cmd_x")
    wrong = PlatformConstants(2.0, 5.0, 302.0, 0.53, 0.53, 23.0)
    a = fit_platform(resp, PC, AC).estimates["inertia_kg_m2"].value
    assert fit_platform(resp, wrong, AC).estimates["inertia_kg_m2"].value == pytest.approx(
        a, rel=1e-12
    )


def test_h1_inside_the_loop_is_biased_and_the_injected_signal_removes_it(tmp_path):
    """Why ``via``: sensor noise circulating in the loop makes plain H1 pa -> ac read the inverse
    of the controller where the noise dominates; the cross-spectra with V_Td do not."""
    rng = np.random.default_rng(5)
    path = platform_file(tmp_path, rng, 0.7, 1.02, 410.0, level_V=0.02)
    b = periodic_blocks([(path, 0, 10**9)], ["cmd_x", "pa_x", "ac_x_inst"], 16.0)
    f = b.f
    sel = (f > 2) & (f < 20)
    truth = _plant(f[sel], 0.7, 1.02, 410.0)
    via = response(b, "pa_x", "ac_x_inst", via="cmd_x").H[sel]
    h1 = response(b, "pa_x", "ac_x_inst").H[sel]
    err = lambda h: np.median(np.abs(20 * np.log10(np.abs(h / truth))))
    assert err(via) < 1.0 and err(h1) > 2 * err(via), (err(via), err(h1))


def test_periodic_blocks_leaves_out_periods_with_lost_samples(tmp_path):
    rng = np.random.default_rng(8)
    x = rng.standard_normal(16000 * 10)
    y = x.copy()
    y[16000 * 4 + 3] = np.nan
    path = _write(tmp_path / "lost.h5", {"a": x, "b": y})
    b = periodic_blocks([(path, 0, 10**9)], ["a", "b"], 16.0, n_blocks=4)
    assert b.weights.sum() == 8  # 10 periods, 1 transient, 1 with the lost sample
    with pytest.raises(TransferError, match="whole 16 s period"):
        periodic_blocks([(path, 0, 16000 * 4)], ["a", "b"], 16.0, n_blocks=4)


def test_a_combined_channel_has_the_spectra_of_the_combination_recorded(tmp_path):
    rng = np.random.default_rng(3)
    a, b = rng.standard_normal(16000), rng.standard_normal(16000)
    c = 0.7 * a - 2.5 * b + 0.1 * rng.standard_normal(16000)
    both = _write(tmp_path / "ab.h5", {"a": a, "b": b, "c": c})
    blocks = block_csd([(both, 0, 16000)], ["a", "b", "c"], 1.0, 4)
    made = blocks.combined({"ab": {"a": 0.7, "b": -2.5}})
    assert made.channels == ("a", "b", "c", "ab")
    ref = _write(tmp_path / "ref.h5", {"ab": 0.7 * a - 2.5 * b, "c": c})
    direct = block_csd([(ref, 0, 16000)], ["ab", "c"], 1.0, 4)
    ab, ci = made.index("ab"), made.index("c")
    np.testing.assert_allclose(made.S[:, :, ab, ab], direct.S[:, :, 0, 0], rtol=1e-9, atol=1e-20)
    np.testing.assert_allclose(made.S[:, :, ab, ci], direct.S[:, :, 0, 1], rtol=1e-9, atol=1e-20)
    with pytest.raises(TransferError, match="'zz' was not analysed"):
        blocks.combined({"x": {"zz": 1.0}})
    with pytest.raises(TransferError, match="already analysed"):
        blocks.combined({"a": {"b": 1.0}})


@settings(max_examples=40, deadline=None)
@given(
    st.lists(st.floats(-1.5, 1.5), min_size=7, max_size=7),
    st.floats(0.005, 0.2),
    st.floats(0.005, 0.2),
)
def test_the_network_fits_jacobian_is_the_residuals_derivative(shift, log_se, phase_se):
    """The fits' analytic Jacobian (eq. 3.28 in logs) against central differences of the
    residual it belongs to, anywhere in the search range of the design network."""
    f = np.geomspace(0.3, 100.0, 40)
    truth = np.log(
        [DESIGN_NETWORK["gain"] * DESIGN_NETWORK["w1_rad_per_s"]]
        + [DESIGN_NETWORK[k] for k in NETWORK_CORNERS]
    )
    H = network_response(f, _network_params(truth)) * np.exp(0.05 + 0.03j)
    ls, ps = np.full(f.size, log_se), np.full(f.size, phase_se)
    x = truth + np.asarray(shift)

    def resid(xx: np.ndarray) -> np.ndarray:
        return _log_residual(network_response(f, _network_params(xx)), H, ls, ps)

    h = 1e-6
    numeric = np.column_stack(
        [(resid(x + h * e) - resid(x - h * e)) / (2 * h) for e in np.eye(x.size)]
    )
    analytic = _log_residual_jacobian(f, x, ls, ps)
    assert analytic.shape == numeric.shape
    assert np.max(np.abs(analytic - numeric)) <= 1e-6 * np.max(np.abs(analytic))


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-1e3, 1e3, allow_nan=False), min_size=3, max_size=20))
def test_jackknife_se_of_the_mean_is_the_standard_error(values):
    """For the mean, the delete-one jackknife's standard error is exactly s / sqrt(n)."""
    x = np.asarray(values)
    loo = np.array([np.delete(x, i).mean() for i in range(x.size)])
    assert jackknife_se(loo) == pytest.approx(x.std(ddof=1) / math.sqrt(x.size), rel=1e-6, abs=1e-9)


def test_a_corner_stopped_at_the_edge_of_its_search_is_unresolved_and_every_interval_covers(
    tmp_path,
):
    """Issue 38 items 1 and 3: in Mode 4 a corner far above the band (w6, 820 Hz, fitted over
    0.3-50 Hz) stopped at the edge of its search; every replicate stopped there too, so it was
    printed resolved with a zero-width interval, and the corners it trades against (w5 read 734
    for 1131) were printed resolved, their intervals holding it fixed where it stopped. Here the
    search is started so that w6 cannot reach its truth: w6 is unresolved with the range the
    record allows, and every corner's interval, resolved or not, covers its truth."""
    rng = np.random.default_rng(12)
    p = dict(DESIGN_NETWORK) | {"w6_rad_per_s": 5155.0, "w5_rad_per_s": 1131.0}
    path = network_file(tmp_path, rng, p)
    resp = response(file_blocks(path, ["ac_x_ctl", "pa_x"], 8.0), "ac_x_ctl", "pa_x")
    start = dict(DESIGN_NETWORK) | {"w6_rad_per_s": 200.0}  # searched 10 .. 4000 rad/s
    fit = fit_network(resp, 0.5, 50.0, start=start)
    w6 = fit.estimates["w6_rad_per_s"]
    assert not w6.resolved and w6.hi > w6.lo, w6
    for k in ("w1_rad_per_s", "w2_rad_per_s", "w3_rad_per_s", "w4_rad_per_s", "w5_rad_per_s"):
        e = fit.estimates[k]
        assert e.hi > e.lo, (k, e)
        assert e.lo <= p[k] <= e.hi, (k, e, p[k])  # resolved or not
    assert w6.lo <= p["w6_rad_per_s"] <= w6.hi, w6


@pytest.mark.parametrize("seed", [1, 12])
def test_a_corner_above_the_band_is_bounded_where_its_profile_crosses_the_limit(tmp_path, seed):
    """Issue 38 A: a corner above the band is held across its search (x1/20 .. x20 of the design)
    on a grid of 7, 2.7x apart; its interval ran out to the first grid point refused, so w6 at
    7139 rad/s fitted over 0.5-100 Hz read [250, 100000] and w5 [442, 3257] - covering by the
    grid's step, not by the data (on 40 drawn rigs 154 times in 154). Bisected to where the
    profile crosses the 95 % limit, the intervals are within 1.5x and still hold the truth."""
    p, fit = drawn_network_fit(tmp_path, seed, 0.5, 100.0)
    for k in ("w5_rad_per_s", "w6_rad_per_s"):
        e = fit.estimates[k]
        assert e.lo <= p[k] <= e.hi, (k, e, p[k])
        assert e.hi / e.lo < 1.5, (k, e)


def test_a_corner_the_band_does_not_see_is_not_measured_and_no_interval_passes_its_search(
    tmp_path,
):
    """Issue 38 A: fitted over 0.5-10 Hz, w6 (7139 rad/s, 1136 Hz) read [61, 1.6e8] rad/s, a
    leave-one-out spread far past the search (x1/20 .. x20 of the design) that no fit can return,
    and counted as a 95 % interval holding its truth. A held corner's interval stays inside its
    search, and one the record narrows nowhere in it is "not measured", with no interval."""
    p, fit = drawn_network_fit(tmp_path, 1, 0.5, 10.0)
    w6 = fit.estimates["w6_rad_per_s"]
    assert not w6.resolved and math.isnan(w6.lo) and math.isnan(w6.hi), w6
    assert w6.why.startswith("not measured"), w6.why
    assert fit.values()["w6_rad_per_s"] is None
    for k in ("w4_rad_per_s", "w5_rad_per_s"):
        e = fit.estimates[k]
        assert math.isnan(e.lo) or e.hi / e.lo <= SEARCH_FACTOR**2 * 1.001, (k, e)


def test_the_fit_names_the_poles_in_order_whatever_order_it_finds_them_in(tmp_path):
    """Eq. 3.28's poles are interchangeable: a fit started with w6 below w4 ended with w6 at 199
    and w4 at 1148, each printed under the other's name. They come back as w1 < w4 < w5 < w6."""
    rng = np.random.default_rng(12)
    p = dict(DESIGN_NETWORK) | {"w6_rad_per_s": 5155.0, "w5_rad_per_s": 1131.0}
    path = network_file(tmp_path, rng, p)
    resp = response(file_blocks(path, ["ac_x_ctl", "pa_x"], 8.0), "ac_x_ctl", "pa_x")
    fit = fit_network(resp, 0.5, 50.0, start=dict(DESIGN_NETWORK) | {"w6_rad_per_s": 200.0})
    w = [fit.estimates[f"w{i}_rad_per_s"].value for i in (1, 4, 5, 6)]
    assert w == sorted(w), w
    assert fit.estimates["w2_rad_per_s"].value < fit.estimates["w3_rad_per_s"].value


def test_a_corner_bounded_on_one_side_only_has_no_bound_on_the_other(tmp_path):
    """Issue 38 A: a held corner whose profile reaches the edge of the fit's search on one side
    was printed with the edge as its 95 % limit (w5 [935, 24000] here): an assumption, which
    held the truth by construction (w5 and w6 113 times in 113 on 40 drawn rigs) and was
    counted as a covering interval. Now that end is open (no bound, null in the JSON) and the
    why says so; the other end is the record's, and still below the truth."""
    p, fit = drawn_network_fit(tmp_path, 2, 0.3, 50.0)
    for k in ("w5_rad_per_s", "w6_rad_per_s"):
        e = fit.estimates[k]
        assert not e.resolved and e.hi == math.inf and 0 < e.lo < p[k], (k, e, p[k])
        assert e.why.startswith("bounded on one side only"), e.why
        assert fit.values()[f"{k}_ci95"][1] is None or not math.isfinite(
            fit.values()[f"{k}_ci95"][1]
        )
