"""The autocollimator's angle noise on the simulated rig: its white level from the NEA for any
1/f knee, the ``flicker_noise`` effect's corner, and the flexible mount shaken by the floor
(DESIGN.md section 8, docs/simhw.md section 4)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.integrate
import scipy.signal

from simhw.config import SimConfig, from_dict
from simhw.effects import get, nominal
from simhw.noise import FlickerNoise, WhiteNoise
from simhw.plant import RelayState, build_plant, discretize
from simhw.sampling import anti_alias_sos, internal_rate
from simhw.simulator import NEA_BAND_HZ, Simulator, Sources, ac_knee, ac_white_psd

URAD = 1e-6


def _h2_ctl(f, w, zeta):
    s = 2j * math.pi * np.asarray(f, float)
    return np.abs(w * w / (s * s + 2 * zeta * w * s + w * w)) ** 2


# --------------------------------------------------------------------------- white level from the NEA
@pytest.mark.parametrize(
    "corner, knee, slope",
    [
        (3.0, 1.0, 1.0),
        (3.0, 0.0, 1.0),
        (1.5, 0.0, 0.8),
        (5.0, 1.0, 1.2),
        (2.0, 0.4, 0.9),
        (10.0, 0.0, 1.2),
    ],
)
def test_white_level_makes_the_nea_in_0_1_100_hz_for_any_knee(corner, knee, slope):
    w, zeta, nea = 264.0, 0.71, 0.451
    white = ac_white_psd(nea, corner, w, zeta, knee=knee, slope=slope)
    # an independent quadrature, split at the knee's corner
    var, _ = scipy.integrate.quad(
        lambda f: white * ac_knee(f, corner, knee, slope) * _h2_ctl(f, w, zeta),
        *NEA_BAND_HZ,
        points=[corner],
        limit=400,
    )
    assert math.sqrt(var) / URAD == pytest.approx(nea, rel=1e-4)


def test_white_level_at_the_plain_knee_is_the_one_it_always_was():
    # the thesis reading, S_w (1 + fc/f), computed as before knees existed: bit for bit
    f = np.geomspace(*NEA_BAND_HZ, 4000)
    gain = np.trapezoid((1.0 + 3.0 / f) * _h2_ctl(f, 264.0, 0.71), f)
    assert ac_white_psd(0.451, 3.0, 264.0, 0.71) == (0.451 * URAD) ** 2 / gain


def test_a_sharper_knee_has_a_higher_white_level_for_the_same_nea():
    soft = ac_white_psd(0.451, 3.0, 264.0, 0.71, knee=1.0)
    sharp = ac_white_psd(0.451, 3.0, 264.0, 0.71, knee=0.0)
    assert sharp > soft


def test_sources_make_the_nac_spectrum_w_times_the_knee():
    cfg = from_dict(
        {
            "autocollimator": {
                "X": {"flicker_knee": 0.0, "flicker_slope": 1.2, "flicker_corner_hz": 2.0}
            }
        }
    )
    ac = cfg.autocollimator["X"]
    src = Sources(cfg, 0, 1 / 2000)
    white = ac_white_psd(
        ac.nea_urad, 2.0, ac.control_filter_rad_per_s, ac.control_filter_zeta, knee=0.0, slope=1.2
    )
    f = np.geomspace(1e-3, 50.0, 500)
    parts = src.spectrum("nac_X", f)
    np.testing.assert_allclose(parts["WhiteNoise"], white, rtol=1e-12)
    k = ac_knee(f, 2.0, 0.0, 1.2)
    assert (
        np.max(np.abs(parts["WhiteNoise"] + parts["FlickerNoise"] - white * k) / (white * k))
        < 0.045
    )


@pytest.mark.parametrize("knee, slope", [(0.0, 1.2), (1.0, 0.8)])
def test_the_clamped_control_channel_shows_the_data_sheet_nea(knee, slope):
    # Table 1's NEA is the control channel's rms in 0.1-100 Hz: the loop open (clamped), the
    # channel reads the angle noise alone. Welch (Hann, no overlap) over M segments: each bin
    # chi^2 with 2M degrees of freedom, Hann bins j apart correlated by rho_j.
    cfg = from_dict({"autocollimator": {"X": {"flicker_knee": knee, "flicker_slope": slope}}})
    ac = cfg.autocollimator["X"]
    rate, nperseg = 1000.0, 2**15
    sim = Simulator(cfg, rate_hz=rate, seed=21, mode=3, channels=("ac_x_ctl",))
    sim.set_clamp(True)
    sim.advance(2000)
    x = np.concatenate([b["ac_x_ctl"] for b in sim.run(24 * nperseg / rate, block_s=60.0)])
    x = x / (ac.control_scale_mV_per_urad * 1e-3)  # urad
    f, p = scipy.signal.welch(
        x, fs=rate, window="hann", nperseg=nperseg, noverlap=0, detrend="constant"
    )
    m = len(x) // nperseg
    band = (f >= NEA_BAND_HZ[0]) & (f <= NEA_BAND_HZ[1])
    df = f[1] - f[0]
    power = np.sum(p[band]) * df
    w2 = scipy.signal.get_window("hann", nperseg) ** 2
    rho = np.abs(np.fft.rfft(w2)[:3]) ** 2 / w2.sum() ** 2
    pb = p[band]
    var = (
        (
            np.sum(pb**2)
            + 2 * rho[1] * np.sum(pb[1:] * pb[:-1])
            + 2 * rho[2] * np.sum(pb[2:] * pb[:-2])
        )
        * df**2
        / m
    )
    assert abs(power - ac.nea_urad**2) < 4 * math.sqrt(var)


# --------------------------------------------------------------------------- the flicker_noise effect
@pytest.mark.parametrize("knee, slope", [(1.0, 1.0), (0.3, 1.1)])
def test_flicker_noise_replaces_the_corner_and_keeps_the_white_level_and_the_knee(knee, slope):
    cfg = from_dict({"autocollimator": {"Y": {"flicker_knee": knee, "flicker_slope": slope}}})
    ac0 = cfg.autocollimator["Y"]
    out = get("flicker_noise").inject(cfg, "Y", corner_hz=8.0)
    ac = out.autocollimator["Y"]
    assert ac.flicker_corner_hz == 8.0
    assert (ac.flicker_knee, ac.flicker_slope, ac.extra_flicker_corner_hz) == (knee, slope, 0.0)
    w, z = ac.control_filter_rad_per_s, ac.control_filter_zeta
    before = ac_white_psd(ac0.nea_urad, ac0.flicker_corner_hz, w, z, knee=knee, slope=slope)
    after = ac_white_psd(ac.nea_urad, 8.0, w, z, knee=knee, slope=slope)
    assert after == pytest.approx(before, rel=1e-12)
    assert ac.nea_urad > ac0.nea_urad  # more 1/f in the band, same white
    assert out.autocollimator["X"] == cfg.autocollimator["X"]


def test_flicker_noise_prior_starts_where_a_nominal_unit_ends():
    eff = get("flicker_noise")
    (p,) = eff.params
    assert (p.name, p.lo, p.hi, p.default, p.log) == ("corner_hz", 5.0, 100.0, 10.0, True)
    assert eff.owns == ("ac_flicker",)


def test_flicker_noise_makes_the_unit_s_own_bank_reach_the_new_corner():
    out = get("flicker_noise").inject(SimConfig(), "X", corner_hz=20.0)
    src = Sources(out, 0, 1 / 2000)
    white, bank, excess = src.parts["nac_X"][:3]
    assert isinstance(bank, FlickerNoise) and bank.level == pytest.approx(
        20.0 * white.sigma**2 * 2 / 2000
    )
    assert excess.level == 0.0
    f = np.array([1.0, 10.0, 100.0])
    k = ac_knee(f, 20.0, 1.0, 1.0)
    got = src.spectrum("nac_X", f)
    assert (got["WhiteNoise"] + got["FlickerNoise"]) / (got["WhiteNoise"] * k) == pytest.approx(
        1.0, rel=0.03
    )


def test_an_old_config_s_extra_flicker_corner_still_adds_its_excess_1_over_f():
    cfg = from_dict({"autocollimator": {"X": {"extra_flicker_corner_hz": 8.0}}})
    src = Sources(cfg, 0, 1 / 2000)
    f = np.array([0.1, 1.0])
    got = src.spectrum("nac_X", f)
    white = got["WhiteNoise"]
    assert got["ExcessFlickerNoise"] == pytest.approx(white * 8.0 / f, rel=0.02)


# --------------------------------------------------------------------------- the mount and the floor
def _mount(excitation, freq=60.0, damping=0.05, base=None):
    cfg = nominal(base)
    ac = cfg.autocollimator["X"]
    ac.mount_freq_hz, ac.mount_damping, ac.mount_excitation = freq, damping, excitation
    return cfg


def test_floor_excitation_enters_the_mount_mode_as_an_angular_acceleration():
    plant = build_plant(_mount(10.0), RelayState(mode=3))
    col = plant.inputs.index("nmount_X")
    assert np.flatnonzero(plant.B[:, col]).tolist() == [plant.states.index("mount_X_v")]
    assert plant.B[plant.states.index("mount_X_v"), col] == 1.0
    # without excitation (or without a mount) the input does not exist: the model is as before
    assert "nmount_X" not in build_plant(_mount(0.0), RelayState(mode=3)).inputs
    assert "nmount_X" not in build_plant(SimConfig(), RelayState(mode=3)).inputs


def test_floor_excitation_psd_puts_excitation_times_w_at_the_undisturbed_mount_s_peak():
    cfg = _mount(25.0, freq=80.0, damping=0.03)
    ac = cfg.autocollimator["X"]
    dt = 1 / 2000
    src = Sources(cfg, 0, dt)
    white = ac_white_psd(
        ac.nea_urad, ac.flicker_corner_hz, ac.control_filter_rad_per_s, ac.control_filter_zeta
    )
    w = 2 * math.pi * 80.0
    (nm,) = src.parts["nmount_X"]
    assert isinstance(nm, WhiteNoise)
    assert nm.sigma**2 * 2 * dt == pytest.approx(25.0 * white * (2 * 0.03 * w * w) ** 2, rel=1e-12)
    # |1/(s^2 + 2 zeta w s + w^2)|^2 at s = jw is 1/(2 zeta w^2)^2
    h = 1 / ((1j * w) ** 2 + 2 * 0.03 * w * (1j * w) + w * w)
    assert nm.sigma**2 * 2 * dt * abs(h) ** 2 == pytest.approx(25.0 * white, rel=1e-12)
    assert src.parts["nmount_Y"][0].sigma == 0.0


def test_floor_excitation_on_x_leaves_every_other_draw_as_it_was():
    # its stream is spawned after every other one: every other source draws the same samples
    # with and without it (a rig without it is the rig from before), and the Y loop is untouched
    a = Simulator(_mount(0.0), rate_hz=500.0, seed=3, mode=3)
    b = Simulator(_mount(50.0), rate_hz=500.0, seed=3, mode=3)
    ba, bb = a.advance(3000), b.advance(3000)
    for ch in ("ac_y_ctl", "ac_y_inst", "pa_y"):
        assert np.array_equal(ba[ch], bb[ch]), ch
    assert not np.array_equal(ba["ac_x_ctl"], bb["ac_x_ctl"])
    sa, sb = Sources(_mount(0.0), 3, 1 / 2000), Sources(_mount(50.0), 3, 1 / 2000)
    assert sa.names == sb.names
    for name in sa.names:
        if name != "nmount_X":
            np.testing.assert_array_equal(sa.take(name, 5000), sb.take(name, 5000), err_msg=name)


def _predicted_psd(cfg, relays, channel, rate, f):
    """The recorded channel's one-sided PSD from the linear model: |H(e^(jw dt))|^2 times each
    noise input's spectrum as the plant sees it (``Sources.spectrum``), through the anti-alias
    filter; at these frequencies the decimator folds nothing of note."""
    m, dt = internal_rate(cfg.sampling, rate)
    plant = build_plant(cfg, relays)
    disc = discretize(plant, dt)
    src = Sources(cfg, 0, dt)
    row = plant.outputs.index(channel)
    z = np.exp(2j * np.pi * f * dt)
    total = np.zeros(len(f))
    for name in src.names:
        if name not in plant.inputs:
            continue
        s_in = sum(src.spectrum(name, f).values())
        if not np.any(s_in):
            continue
        col = plant.inputs.index(name)
        h = np.array(
            [
                plant.C[row] @ np.linalg.solve(zk * np.eye(len(disc.Ad)) - disc.Ad, disc.Bd[:, col])
                + plant.D[row, col]
                for zk in z
            ]
        )
        total += np.abs(h) ** 2 * s_in
    sos = anti_alias_sos(cfg.sampling.anti_alias_poles, cfg.sampling.anti_alias_fraction, rate, m)
    return total * np.abs(scipy.signal.sosfreqz(sos, worN=f, fs=rate * m)[1]) ** 2


@pytest.mark.parametrize("clamped", [True, False], ids=["loop open", "mode 3"])
def test_the_ac_channel_s_peak_at_the_mount_rises_as_the_model_predicts(clamped):
    rate, nperseg, freq = 1000.0, 4096, 60.0
    f_band = (55.0, 65.0)
    measured, predicted = {}, {}
    for excitation in (0.0, 30.0):
        cfg = _mount(excitation, freq=freq)
        sim = Simulator(cfg, rate_hz=rate, seed=12, mode=3, channels=("ac_x_ctl",))
        if clamped:
            sim.set_clamp(True)
        sim.advance(1000)
        x = np.concatenate([b["ac_x_ctl"] for b in sim.run(32 * nperseg / rate, block_s=60.0)])
        f, p = scipy.signal.welch(x, fs=rate, window="hann", nperseg=nperseg, noverlap=0)
        sel = (f >= f_band[0]) & (f <= f_band[1])
        m, b = len(x) // nperseg, int(sel.sum())
        pred = _predicted_psd(cfg, RelayState(mode=3, clamped=clamped), "ac_x_ctl", rate, f[sel])
        ratio = float(np.mean(p[sel] / pred))
        # Hann bins j apart correlate by rho_j; each is chi^2_2m / 2m
        w2 = scipy.signal.get_window("hann", nperseg) ** 2
        rho = np.abs(np.fft.rfft(w2)[:4]) ** 2 / w2.sum() ** 2
        sigma = math.sqrt(sum((b - abs(j)) * rho[abs(j)] for j in range(-3, 4)) / (m * b * b))
        assert abs(ratio - 1.0) < 4 * sigma, (excitation, ratio, sigma)
        measured[excitation], predicted[excitation] = np.mean(p[sel]), np.mean(pred)
    rise = measured[30.0] / measured[0.0]
    assert predicted[30.0] / predicted[0.0] > 3.0  # the floor shows at the mount
    assert rise == pytest.approx(predicted[30.0] / predicted[0.0], rel=6 * sigma)


def test_the_gap_model_builds_spectra_for_a_shaken_mount():
    # procedures.analysis.gap.model reads each noise source's spectrum; the floor input is none
    # of its nuisance parts and goes to "fixed"
    from procedures.analysis.gap.grid import make_grid
    from procedures.analysis.gap.model import SpectralModel

    rate = 1000.0
    grid = make_grid(rate, int(300 * rate))
    channels = ("ac_x_ctl", "ac_x_inst", "gyro_x", "pa_x")
    model = SpectralModel(grid, channels, 3, "X")
    still, shaken = model(_mount(0.0)), model(_mount(30.0))
    at = (grid.band_center_hz > 57.0) & (grid.band_center_hz < 63.0)
    row = channels.index("ac_x_ctl")
    assert np.all(np.isfinite(shaken.parts["fixed"]))
    assert np.all(shaken.total()[row, at] > 3.0 * still.total()[row, at])
    np.testing.assert_allclose(shaken.parts["ac"], still.parts["ac"], rtol=1e-9)
