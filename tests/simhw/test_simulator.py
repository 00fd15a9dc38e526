"""The simulator as a whole: determinism, block independence, clocks, modes, the ADC."""

import numpy as np
import pytest

from simhw.config import SimConfig
from simhw.plant import CHANNELS, RelayState
from simhw.simulator import Simulator
from simhw.virtual_clock import PacedClock


def _volts(sim, sizes):
    return np.concatenate([sim.advance(n).volts for n in sizes])


def test_same_seed_same_output_different_seed_different_output():
    a = _volts(Simulator(rate_hz=200.0, seed=42), [400])
    b = _volts(Simulator(rate_hz=200.0, seed=42), [400])
    c = _volts(Simulator(rate_hz=200.0, seed=43), [400])
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


def test_output_does_not_depend_on_how_the_run_is_cut_into_blocks():
    whole = _volts(Simulator(rate_hz=200.0, seed=9), [1000])
    pieces = _volts(Simulator(rate_hz=200.0, seed=9), [1, 7, 250, 3, 539, 200])
    assert np.array_equal(whole, pieces)


def test_set_points_inside_a_block_are_the_block_split_at_them():
    """``advance(n, events)`` steps a set-point inside the block: the samples are those of the
    run cut at every event, to the bit (the sim rig's streams rest on it)."""

    def vtd(v):
        return lambda sim: sim.set_command_torque_V("X", v)

    def gc(v):
        return lambda sim: sim.set_ac_bias_V("Y", v)

    split = Simulator(rate_hz=200.0, seed=5, mode=3)
    parts = [split.advance(3).volts]
    for fn, k in ((vtd(0.4), 17), (gc(-0.2), 1), (vtd(-0.3), 79)):
        fn(split)
        parts.append(split.advance(k).volts)
    whole = Simulator(rate_hz=200.0, seed=5, mode=3)
    got = whole.advance(100, [(3, vtd(0.4)), (20, gc(-0.2)), (21, vtd(-0.3))]).volts
    assert np.array_equal(got, np.concatenate(parts))
    assert whole.vtd["X"] == -0.3 and whole.gamma_c["Y"] == -0.2
    # set-points only (the sim rig's streams): the pieces in one kernel call, the same samples,
    # and the block after them too
    one = Simulator(rate_hz=200.0, seed=5, mode=3)
    events = [(3, vtd(0.4)), (20, gc(-0.2)), (21, vtd(-0.3))]
    assert np.array_equal(one.advance(100, events, setpoints=True).volts, got)
    assert np.array_equal(one.advance(37).volts, whole.advance(37).volts)
    assert not np.array_equal(got, Simulator(rate_hz=200.0, seed=5, mode=3).advance(100).volts)
    with pytest.raises(ValueError, match="ordered within 0..99"):
        whole.advance(100, [(50, vtd(0.1)), (10, vtd(0.2))])
    with pytest.raises(ValueError, match="ordered within 0..99"):
        whole.advance(100, [(100, vtd(0.1))])


def test_a_mode_change_inside_a_block_is_the_block_split_at_it():
    """An event that switches the plant (a relay state: other noise inputs) inside a block: the
    noise the block drew ahead for the old plant goes back to its streams, and the samples are
    those of the run cut there, to the bit, in the blocks after it too."""

    def mode(m):
        return lambda sim: sim.set_mode(m)

    split = Simulator(rate_hz=200.0, seed=4, mode=1)
    parts = [split.advance(31).volts]
    mode(3)(split)
    parts += [split.advance(69).volts, split.advance(57).volts]
    whole = Simulator(rate_hz=200.0, seed=4, mode=1)
    got = [whole.advance(100, [(31, mode(3))]).volts, whole.advance(57).volts]
    assert np.array_equal(np.concatenate(got), np.concatenate(parts))


def test_paced_clock_gives_the_same_samples_and_keeps_to_wall_time():
    import time

    fast = _volts(Simulator(rate_hz=100.0, seed=5), [30])
    t0 = time.monotonic()
    paced_sim = Simulator(rate_hz=100.0, seed=5, clock=PacedClock())
    paced = _volts(paced_sim, [10, 10, 10])
    elapsed = time.monotonic() - t0
    assert np.array_equal(fast, paced)
    assert paced_sim.clock.now == pytest.approx(0.3)
    assert elapsed >= 0.29  # never ahead of the wall clock (a lower bound, not a timing target)


def test_block_times_follow_one_time_base_from_zero():
    sim = Simulator(rate_hz=50.0, seed=1)
    starts = [sim.advance(n).t0 for n in (10, 25, 5)]
    assert starts == pytest.approx([0.0, 0.2, 0.7])


@pytest.mark.parametrize("mode", [0, 7, -1, 8])
def test_disallowed_modes_are_refused_with_the_mode_named(mode):
    sim = Simulator(rate_hz=50.0)
    with pytest.raises(ValueError, match=f"mode {mode} is not allowed"):
        sim.set_mode(mode)
    assert sim.mode == 3
    with pytest.raises(ValueError, match=f"mode {mode}"):
        RelayState(mode=mode)


def _rms_urad(sim, channel, scale_V_per_urad, seconds=20.0):
    v = np.concatenate([b[channel] for b in sim.run(seconds, seconds)])
    return float(v.std() / scale_V_per_urad)


def test_mode4_gyro_control_holds_the_platform_after_spin_up_and_caging():
    cfg = SimConfig()
    cfg.gyros.spin_up_time_s = 30.0
    sim = Simulator(cfg, 200.0, seed=3, mode=1)
    sim.set_mode(2)
    sim.advance(200 * 40)
    sim.set_mode(3)
    sim.advance(200 * 120)  # caging loops settle
    assert sim.gyros_at_speed
    sim.set_mode(4)
    sim.advance(200 * 120)
    # Gyro-stabilized and autocollimator-supervised: the optical error stays at noise level.
    assert _rms_urad(sim, "ac_x_ctl", 5.70e-3) < 5.0
    assert _rms_urad(sim, "ac_y_ctl", 5.99e-3) < 5.0


def test_mode6_opens_the_stabilization_loop():
    """External stabilization: the compensation input is open, so a command torque is no
    longer fought by the loop and the platform settles on its bearing spring."""
    sim = Simulator(rate_hz=200.0, seed=2, mode=6)
    sim.set_command_torque_V("X", 1.0)  # K_d V_Td K_p K_m / R_a = 0.0275 N m
    sim.advance(200 * 30)
    angle = np.mean(np.concatenate([b["ac_x_inst"] for b in sim.run(5, 5)])) / 5.63e-3  # urad
    # The Dahl bearing's small-motion spring is 410 N m/rad, but this torque is near T_o:
    # the gimbal moves well beyond the spring's 67 urad, into Coulomb sliding.
    assert angle > 67.0


def test_mode3_rejects_a_command_torque_as_a_stiff_loop():
    sim = Simulator(rate_hz=200.0, seed=2, mode=3)
    sim.set_command_torque_V("X", 1.0)
    sim.advance(200 * 30)
    angle = np.mean(np.concatenate([b["ac_x_inst"] for b in sim.run(5, 5)])) / 5.63e-3
    assert abs(angle) < 5.0


def test_overrange_is_flagged_and_clipped_never_wrapped():
    sim = Simulator(rate_hz=100.0, seed=1)
    sim.set_range("ac_x_inst", 0.01)
    # The loop nulls the biased control channel, so the platform turns by -0.5 V / K_AC
    # (-88 urad) and the unbiased instrumentation channel reads about -0.5 V: beyond +-10 mV.
    sim.set_ac_bias_V("X", 0.5)
    sim.advance(300)
    block = sim.advance(100)
    j = CHANNELS.index("ac_x_inst")
    assert block.overrange[:, j].all()
    q = 0.02 / 2**16
    assert np.all(block.volts[:, j] == pytest.approx(-0.01, abs=q))  # clipped at the end code
    assert not block.overrange[:, CHANNELS.index("ac_y_inst")].any()


def test_bad_settings_are_refused_with_the_value_named():
    sim = Simulator(rate_hz=100.0)
    with pytest.raises(ValueError, match="unknown gyro channel 'W'"):
        sim.set_torquer_bias_V("W", 1.0)
    with pytest.raises(ValueError, match="table tilt 120"):
        sim.set_table(tilt_deg=120.0)
    with pytest.raises(ValueError, match="ADC range 3.0 V for gyro_x"):
        sim.set_range("gyro_x", 3.0)
    with pytest.raises(ValueError, match="sample rate"):
        Simulator(rate_hz=0.0)


def test_inputs_drawn_ahead_are_the_parts_drawn_block_by_block():
    """``Sources`` draws each input ahead in long runs; every part keeps its own stream, so the
    samples are those the parts give when asked block by block."""
    from simhw.simulator import Sources

    cfg = SimConfig()
    ahead, direct = Sources(cfg, 11, 1e-4), Sources(cfg, 11, 1e-4)
    for n in (3, 40, Sources.AHEAD + 5, 1, 700):
        for name in ("nac_X", "np_Y", "wrand_Z", "md_X"):
            want = np.zeros(n)
            for part in direct.parts[name]:
                want += part.take(n)
            assert np.array_equal(ahead.take(name, n), want), (name, n)
    with pytest.raises(RuntimeError, match="drawn"):
        ahead.initial("nac_X")
    # what was taken and given back is taken again; the stream goes on after it
    for n in (5, Sources.AHEAD + 9):
        first = ahead.take("wrand_X", n)
        ahead.unread("wrand_X", first[2:])
        again = ahead.take("wrand_X", n + 3)
        assert np.array_equal(again[: n - 2], first[2:])
        ahead.unread("wrand_X", again)
        assert np.array_equal(ahead.take("wrand_X", n + 3), again)
