"""``procedures.analysis.roots``: the loop closed over identified parts, against the simulator's
own state-space model (``simhw.plant.linearized_poles``, built independently from the same
physics) for drawn rigs, and the naming of Tables 5 and 6's roots."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.rig_datasheet import AutocollimatorConstants, PlatformConstants
from procedures.analysis.roots import GyroCaging, LoopParts, name_roots
from simhw.config import SimConfig
from simhw.plant import linearized_poles

BAND = (2 * np.pi * 0.3, 2 * np.pi * 50.0)


def _drawn(rng, axis):
    cfg = SimConfig()
    pa, br, comp = cfg.platform[axis], cfg.bearing[axis], cfg.compensation
    pa.inertia_kg_m2 *= float(rng.uniform(0.7, 1.4))
    br.model, br.stiffness_Nm_per_rad = "spring", float(rng.uniform(250, 700))
    comp.w2_rad_per_s, comp.w3_rad_per_s = float(rng.uniform(7, 14)), float(rng.uniform(22, 40))
    comp.w4_rad_per_s = float(rng.uniform(150, 260))
    g = cfg.gyro[axis]
    g.pickoff_scale_mV_per_urad = float(rng.uniform(5.5, 7.5))
    return cfg


def _parts(cfg, axis, mode, cage=True):
    p, comp, ac = cfg.platform[axis], cfg.compensation, cfg.autocollimator[axis]
    pc = PlatformConstants(
        p.inertia_kg_m2,
        p.gyro_damping_Nms,
        p.amp_gain,
        p.motor_torque_Nm_per_A,
        p.back_emf_V_s,
        p.armature_ohm,
        p.armature_H,
        p.command_divider,
    )
    acc = AutocollimatorConstants(
        ac.control_scale_mV_per_urad,
        ac.inst_scale_mV_per_urad,
        ac.control_filter_rad_per_s,
        ac.control_filter_zeta,
    )
    net = {
        "gain": 1.0,
        **{
            k: getattr(comp, k)
            for k in (
                "w1_rad_per_s",
                "w2_rad_per_s",
                "w3_rad_per_s",
                "w4_rad_per_s",
                "w5_rad_per_s",
                "w6_rad_per_s",
            )
        },
    }
    sensor = (
        ac.control_scale_mV_per_urad if mode == 3 else cfg.gyro[axis].pickoff_scale_mV_per_urad
    ) * 1e3
    g = cfg.gyro[axis]
    caging = (
        None
        if mode == 3 or not cage
        else GyroCaging(g.caging_natural_freq_rad_per_s, g.caging_zeta, g.restraint_time_s)
    )
    parts = LoopParts(
        net,
        p.inertia_kg_m2,
        p.gyro_damping_Nms,
        cfg.bearing[axis].stiffness_Nm_per_rad,
        sensor,
        caging,
    )
    return parts.roots(pc, acc, "ctl" if mode == 3 else "gyro")


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("axis", ["X", "Y"])
def test_mode3_closure_is_the_state_space_model_exactly(seed, axis):
    """In Mode 3 the axis loop is exactly network, amplifier-motor-gimbal and control channel:
    every in-band root agrees with the state-space model's to 1e-6."""
    cfg = _drawn(np.random.default_rng(seed), axis)
    lin = linearized_poles(cfg, 3, axis)
    got = _parts(cfg, axis, 3)
    for p in got:
        if BAND[0] <= abs(p) <= BAND[1]:
            assert np.min(np.abs(lin - p)) / abs(p) < 1e-6, (p, lin)


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("axis", ["X", "Y"])
def test_gyro_mode_closure_with_the_caged_float_is_the_loop_alone_exactly(seed, axis):
    """In modes 4 and 5 the pickoff's float is caged through the autocollimator inside the loop:
    with it every in-band root is the state-space model's loop alone to 1e-6 (without it c1
    moved up to 4.4 %). The loop alone leaves out the X-Y gyro's viscous cross-axis coupling,
    which ties the X and Y loops; until issue 38 ``linearized_poles`` kept the coupling's
    1 / (1 + c_x c_y / h^2) on the axis's float and left out the other loop (the pair 2 % off
    both the loop alone and the coupled rig)."""
    cfg = _drawn(np.random.default_rng(100 + seed), axis)
    lin = linearized_poles(cfg, 4, axis)
    if np.max(lin.real) >= 0:
        pytest.skip("drawn rig unstable in Mode 4")
    got = _parts(cfg, axis, 4)
    named = name_roots(got, *BAND)
    assert set(named) == {"c1", "platform_pair", "c4"}
    for p in got:
        if BAND[0] <= abs(p) <= BAND[1]:
            assert np.min(np.abs(lin - p)) / abs(p) < 1e-6, (p, lin)
    crude = name_roots(_parts(cfg, axis, 4, cage=False), *BAND)
    assert all(np.min(np.abs(lin - p)) / abs(p) < 0.05 for p in crude.values())


def test_the_coupled_rigs_gyro_mode_pair_is_not_the_loop_alones():
    """What the loop alone leaves out is real: with spring bearings the coupled rig's X pair in
    Mode 4 (every axis, ``axis=None``) lies 0.54 % (complex distance over modulus) from the loop
    alone's on the thesis rig, and 2.7 % where X's pair (55 rad/s at 0.5 kg m^2) nears Y's (69):
    the two loops' pairs repel."""
    cfg = SimConfig()
    for b in cfg.bearing.values():
        b.model = "spring"
    for inertia, least in ((0.70, 0.004), (0.50, 0.02)):
        cfg.platform["X"].inertia_kg_m2 = inertia
        alone = name_roots(linearized_poles(cfg, 4, "X"), *BAND)["platform_pair"]
        rig = linearized_poles(cfg, 4)
        nearest = rig[np.argmin(np.abs(rig - alone))]
        assert abs(nearest - alone) / abs(alone) > least, (inertia, alone, nearest)


def test_roots_are_named_by_their_place_in_the_loop():
    roots = np.array(
        [-0.2, -5.5, -10 + 43j, -10 - 43j, -190 + 186j, -190 - 186j, -161.0, -1070.0, -5000.0]
    )
    named = name_roots(roots, *BAND)
    assert named == {
        "platform_pair": complex(-10, 43),
        "c1": complex(-5.5, 0),
        "c4": complex(-161.0, 0),
    }
    # an unstable root is never named; no pair in the band, nothing named
    assert name_roots(np.array([2.0 + 40j, 2.0 - 40j, -5.0]), *BAND) == {}
