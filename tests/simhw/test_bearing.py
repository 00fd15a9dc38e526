"""Gimbal bearing torque models: Dahl's solid friction (Klinger 1974, Ch. V F, eq. 5.2).

Dahl's model: dT/dtheta = eta (T - To)^2 while theta increases and eta (T + To)^2 while it
decreases. ``dahl_step`` integrates it exactly over one monotone increment.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from simhw.bearing import BearingLinearPart, dahl_step, dahl_stiffness, linear_part
from simhw.config import Bearing

FAST = settings(max_examples=100, deadline=None)

To_s = st.floats(1e-3, 1.0)
eta_s = st.floats(1e3, 1e8)
Tbar_s = st.floats(-0.99, 0.99)  # T / To, inside the Coulomb limits
# eta To |dtheta|: from the elastic (<< 1) to the fully slipping (>> 1) regime.
slip_s = st.floats(1e-6, 30.0)


def _dahl_rhs(s, x, direction):
    """Eq. 5.2 in normalized form: x = T / To, s = eta To theta."""
    return [(x[0] - direction) ** 2]


def _integrate(T0, dtheta, To, eta):
    """Eq. 5.2 by numerical integration over theta in [0, dtheta]."""
    direction = 1.0 if dtheta > 0 else -1.0
    sol = solve_ivp(
        _dahl_rhs,
        (0.0, eta * To * dtheta),
        [T0 / To],
        args=(direction,),
        method="DOP853",
        rtol=1e-12,
        atol=1e-14,
        max_step=0.25,
    )
    assert sol.success
    return To * sol.y[0, -1]


def _tm_over_to(theta0_bar):
    """Peak torque of the steady hysteresis loop for theta = theta0 sin(wt), eq. 5.9."""
    return (math.sqrt(1.0 + 4.0 * theta0_bar**2) - 1.0) / (2.0 * theta0_bar)


# --------------------------------------------------------------------------- exact update
@FAST
@given(Tbar_s, slip_s, st.sampled_from([1.0, -1.0]), To_s, eta_s)
def test_dahl_step_agrees_with_numerical_integration_of_eq_5_2(tbar, slip, sign, To, eta):
    T0 = tbar * To
    d = sign * slip / (eta * To)
    assert dahl_step(T0, d, To, eta) == pytest.approx(_integrate(T0, d, To, eta), abs=1e-8 * To)


@FAST
@given(Tbar_s, To_s, eta_s)
def test_zero_increment_leaves_the_torque_unchanged(tbar, To, eta):
    assert dahl_step(tbar * To, 0.0, To, eta) == tbar * To


@FAST
@given(Tbar_s, slip_s, To_s, eta_s)
def test_torque_moves_with_the_angle(tbar, slip, To, eta):
    T0, d = tbar * To, slip / (eta * To)
    assert dahl_step(T0, d, To, eta) > T0
    assert dahl_step(T0, -d, To, eta) < T0


@FAST
@given(Tbar_s, slip_s, st.sampled_from([1.0, -1.0]), To_s, eta_s)
def test_reversing_the_motion_mirrors_the_torque(tbar, slip, sign, To, eta):
    d = sign * slip / (eta * To)
    assert dahl_step(-tbar * To, -d, To, eta) == pytest.approx(
        -dahl_step(tbar * To, d, To, eta), abs=1e-12 * To
    )


@FAST
@given(Tbar_s, slip_s, slip_s, st.sampled_from([1.0, -1.0]), To_s, eta_s)
def test_two_steps_in_one_direction_equal_one_step_of_their_sum(tbar, s1, s2, sign, To, eta):
    d1, d2 = sign * s1 / (eta * To), sign * s2 / (eta * To)
    T0 = tbar * To
    two = dahl_step(dahl_step(T0, d1, To, eta), d2, To, eta)
    assert two == pytest.approx(dahl_step(T0, d1 + d2, To, eta), abs=1e-10 * To)


@settings(max_examples=100, deadline=None)
@given(Tbar_s, st.lists(st.floats(-30.0, 30.0), min_size=1, max_size=60), To_s, eta_s)
def test_torque_never_leaves_the_coulomb_limits(tbar, slips, To, eta):
    T = tbar * To
    for s in slips:
        T = dahl_step(T, s / (eta * To), To, eta)
        assert abs(T) < To


# --------------------------------------------------------------------------- limits
@pytest.mark.parametrize("sign", [1.0, -1.0])
@pytest.mark.parametrize("To, eta", [(0.016, 1.6e6), (0.016, 1.48e6), (0.1, 1e4), (0.002, 1e8)])
def test_small_motion_is_a_spring_of_stiffness_eta_To_squared(To, eta, sign):
    k = dahl_stiffness(To, eta)
    assert k == eta * To * To
    d = sign * 1e-6 / (eta * To)  # eta To |d| = 1e-6: deep in the elastic regime
    assert dahl_step(0.0, d, To, eta) == pytest.approx(k * d, rel=1e-5)


def test_default_x_bearing_is_a_410_Nm_per_rad_spring_for_nanoradian_motion():
    b = Bearing()
    assert dahl_step(0.0, 1e-9, b.To_Nm, b.eta_per_Nm) == pytest.approx(409.6e-9, rel=1e-4)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_large_monotone_motion_reaches_the_coulomb_torque(sign):
    To, eta = 0.016, 1.6e6
    T = 0.0
    for _ in range(1000):  # 1000 x 10 urad = 10 mrad, eta To theta = 256
        T = dahl_step(T, sign * 1e-5, To, eta)
    assert T == pytest.approx(sign * To, rel=1e-2)
    assert abs(T) < To
    # Exactly: To - T = 1 / (1/To + eta theta).
    assert sign * To - T == pytest.approx(sign / (1 / To + eta * 1e-2), rel=1e-9)


# --------------------------------------------------------------------------- hysteresis loop
@FAST
@given(st.floats(1e-3, 1e3), To_s, eta_s)
def test_symmetric_loop_peak_of_eq_5_9_is_a_fixed_point_of_a_half_cycle(theta0_bar, To, eta):
    """From -Tm at -theta0, a sweep to +theta0 ends at +Tm (the steady loop of eq. 5.5a/5.9)."""
    Tm = To * _tm_over_to(theta0_bar)
    theta0 = theta0_bar / (eta * To)
    assert dahl_step(-Tm, 2 * theta0, To, eta) == pytest.approx(Tm, rel=1e-9)
    assert dahl_step(Tm, -2 * theta0, To, eta) == pytest.approx(-Tm, rel=1e-9)


@settings(max_examples=30, deadline=None)
@given(st.floats(0.5, 20.0))
def test_sinusoidal_sweep_settles_to_the_hysteresis_loop_of_eq_5_9(theta0_bar):
    To, eta = 0.016, 1.6e6
    theta0 = theta0_bar / (eta * To)
    n_per_cycle, cycles = 200, 5
    theta = theta0 * np.sin(2 * np.pi * np.arange(n_per_cycle * cycles + 1) / n_per_cycle)
    T, torque = 0.0, [0.0]
    for d in np.diff(theta):
        T = dahl_step(T, float(d), To, eta)
        torque.append(T)
    last = np.array(torque[-n_per_cycle - 1 :])
    expected = To * _tm_over_to(theta0_bar)
    assert last.max() == pytest.approx(expected, rel=1e-4)
    assert -last.min() == pytest.approx(expected, rel=1e-4)
    # A hysteresis loop, not a curve: at theta = 0 the friction torque opposes the motion,
    # positive while theta rises and negative while it falls.
    rising, falling = last[0], last[n_per_cycle // 2]
    assert rising > 0.1 * expected and falling < -0.1 * expected


def test_peak_torque_of_eq_5_9_tends_to_the_spring_and_the_coulomb_limits():
    # theta0_bar -> 0: Tm = eta To^2 theta0 (spring); theta0_bar -> inf: Tm -> To.
    assert _tm_over_to(1e-4) == pytest.approx(1e-4, rel=1e-6)
    assert _tm_over_to(1e4) == pytest.approx(1.0, rel=1e-3)


# --------------------------------------------------------------------------- Coulomb limit
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_step_from_the_coulomb_limit_stays_there_and_a_reversal_leaves_it(sign):
    To, eta = 0.016, 1.6e6
    T = dahl_step(0.0, sign * 1e12, To, eta)  # rounds to the limit exactly in floating point
    assert T == sign * To
    assert dahl_step(T, sign * 1e-6, To, eta) == sign * To
    back = dahl_step(T, -sign * 1e-9, To, eta)
    assert abs(back) < To
    assert back == pytest.approx(sign * To - sign * 4 * dahl_stiffness(To, eta) * 1e-9, rel=1e-6)


@settings(max_examples=100, deadline=None)
@given(Tbar_s, st.lists(st.floats(-1e20, 1e20), min_size=1, max_size=40), To_s, eta_s)
def test_any_increments_keep_the_torque_finite_and_within_the_coulomb_limits(tbar, slips, To, eta):
    T = tbar * To
    for s in slips:
        T = dahl_step(T, s / (eta * To), To, eta)
        # At the limit a reversal's 1/(1/(2 To)) may round an ulp or two past it; never more.
        assert math.isfinite(T) and abs(T) <= To * (1 + 1e-15)


# --------------------------------------------------------------------------- linear part
def test_linear_part_of_model_none_is_zero():
    assert linear_part(Bearing(model="none")) == BearingLinearPart(0.0, 0.0, False)


def test_linear_part_of_model_viscous_is_its_damping():
    assert linear_part(Bearing(model="viscous", damping_Nms=0.3)) == BearingLinearPart(
        0.0, 0.3, False
    )


def test_linear_part_of_model_spring_is_its_stiffness():
    assert linear_part(Bearing(model="spring", stiffness_Nm_per_rad=380.0)) == BearingLinearPart(
        380.0, 0.0, False
    )


def test_linear_part_of_model_dahl_is_the_small_motion_stiffness_plus_a_residual():
    b = Bearing(model="dahl", To_Nm=0.02, eta_per_Nm=1e6, stiffness_Nm_per_rad=1.0, damping_Nms=5.0)
    assert linear_part(b) == BearingLinearPart(400.0, 0.0, True)


def test_linear_part_of_unknown_model_raises_value_error_naming_it():
    with pytest.raises(ValueError, match="'coulomb'"):
        linear_part(Bearing(model="coulomb"))
