"""A simulator asked for a few channels gives exactly what the whole rig gives on them
(simhw.reduction): with every catalogue effect on the recorded axis or the other one, across
mode changes, console settings, a rate change and the truth channels."""

import numpy as np
import pytest

from simhw import effects
from simhw.config import SimConfig
from simhw.plant import CHANNELS
from simhw.reduction import kept
from simhw.simulator import Simulator

AXIS_CHANNELS = {
    "X": ("ac_x_ctl", "ac_x_inst", "gyro_x", "pa_x"),
    "Y": ("ac_y_ctl", "ac_y_inst", "gyro_y", "pa_y"),
}
EFFECTS = sorted(n for n in effects.catalogue() if n != "none")


def _pair(cfg, channels, **kw):
    return Simulator(cfg, seed=kw.pop("seed", 7), channels=channels, **kw), Simulator(
        cfg, seed=7, **kw
    )


def _same(reduced, full, sizes):
    """Advance both by ``sizes`` samples; the reduced run's channels equal the full run's, bit for bit."""
    for n in sizes:
        r, f = reduced.advance(n), full.advance(n)
        assert r.channels == reduced.channels
        for c in r.channels:
            assert np.array_equal(r[c], f[c]), c
        assert np.array_equal(r.overrange, f.overrange[:, [CHANNELS.index(c) for c in r.channels]])
        for c in r.truth:
            assert np.array_equal(r.truth[c], f.truth[c]), c


def _values(effect):
    """A mid-range value of each parameter: the effect is really there."""
    return {
        p.name: float(np.sqrt(p.lo * p.hi)) if p.log and p.lo > 0 else 0.5 * (p.lo + p.hi)
        for p in effect.params
    }


@pytest.mark.parametrize("effect_axis", ["X", "Y"])
@pytest.mark.parametrize("name", EFFECTS)
def test_x_channels_are_the_full_rigs_with_an_effect_on_either_axis(name, effect_axis):
    effect = effects.get(name)
    cfg = effect.inject(effects.nominal(), effect_axis, **_values(effect))
    _same(*_pair(cfg, AXIS_CHANNELS["X"], rate_hz=500.0), [700, 800])


@pytest.mark.parametrize("axis", ["X", "Y"])
def test_each_axis_alone_is_the_full_rigs_with_dahl_bearings(axis):
    _same(*_pair(SimConfig(), AXIS_CHANNELS[axis], rate_hz=500.0), [1000, 500])


def test_mode_changes_settings_and_a_rate_change_keep_the_reduced_run_exact():
    reduced, full = _pair(SimConfig(), ("gyro_x", "torq_x", "pa_x", "cmd_x"), rate_hz=200.0, mode=3)
    _same(reduced, full, [200])
    for sim in (reduced, full):
        sim.set_torquer_bias_V("X", 1.5)
        sim.set_command_torque_V("X", 0.2)
        sim.set_caging_inhibit("X", True)
    _same(reduced, full, [300])
    for mode in (1, 2, 3, 5, 6, 3):
        for sim in (reduced, full):
            sim.set_mode(mode)
        _same(reduced, full, [150])
    for sim in (reduced, full):
        sim.set_rate(100.0)
        sim.set_table(tilt_deg=45.0, spindle_deg=30.0)
    _same(reduced, full, [250])


def test_truth_and_single_channels_of_other_parts_of_the_rig():
    reduced, full = _pair(SimConfig(), ("ac_z",), rate_hz=250.0, truth=True)
    _same(reduced, full, [500])
    _same(*_pair(SimConfig(), ("gyro_xrd", "torq_z"), rate_hz=250.0), [500])


def test_a_single_axis_keeps_fewer_states_than_the_rig():
    k = kept(SimConfig(), AXIS_CHANNELS["X"])
    assert "theta_X" in k.states and "theta_Z" not in k.states
    assert not any(s.endswith("_Z") for s in k.states)


@pytest.mark.parametrize("channels", [("ac_x_ctl", "gyro_q"), (), ("pa_x", "pa_x")])
def test_bad_channel_lists_are_refused_with_the_valid_names(channels):
    with pytest.raises(ValueError, match="the channels are ac_x_ctl"):
        Simulator(SimConfig(), 100.0, channels=channels)
