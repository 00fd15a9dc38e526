"""Rotary-table geometry: platform axes in ENU, earth rate and gravity on them (Ch. II C.4.b)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from simhw.geometry import (
    earth_rate_platform,
    platform_axes_enu,
    polar_tilt_deg,
    specific_force_platform,
)

FAST = settings(max_examples=150, deadline=None)
OMEGA = 7.292115e-5
angle_s = st.floats(-2 * math.pi, 2 * math.pi)
tilt_s = st.floats(0.0, math.pi / 2)
lat_s = st.floats(-89.0, 89.0)
offset_s = st.floats(math.radians(-10), math.radians(10))


@FAST
@given(tilt_s, angle_s, offset_s)
def test_platform_axes_are_orthonormal_and_right_handed(tilt, spindle, offset):
    axes = platform_axes_enu(tilt, spindle, offset)
    assert axes.shape == (3, 3)
    np.testing.assert_allclose(axes @ axes.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(np.cross(axes[0], axes[1]), axes[2], atol=1e-12)
    assert np.linalg.det(axes) == pytest.approx(1.0, abs=1e-12)


def test_zero_angles_put_X_north_Y_west_Z_up():
    np.testing.assert_allclose(
        platform_axes_enu(0.0, 0.0, 0.0), [[0, 1, 0], [-1, 0, 0], [0, 0, 1]], atol=1e-15
    )


@FAST
@given(lat_s, angle_s, offset_s)
def test_level_table_earth_rate_follows_spindle_minus_offset(lat_deg, spindle, offset):
    lat = math.radians(lat_deg)
    w = earth_rate_platform(lat, OMEGA, platform_axes_enu(0.0, spindle, offset))
    a = spindle - offset
    np.testing.assert_allclose(
        w,
        [
            OMEGA * math.cos(lat) * math.cos(a),
            -OMEGA * math.cos(lat) * math.sin(a),
            OMEGA * math.sin(lat),
        ],
        rtol=0,
        atol=1e-12 * OMEGA,
    )


@FAST
@given(tilt_s, angle_s, offset_s, lat_s)
def test_earth_rate_keeps_its_magnitude_on_the_platform_axes(tilt, spindle, offset, lat_deg):
    w = earth_rate_platform(math.radians(lat_deg), OMEGA, platform_axes_enu(tilt, spindle, offset))
    assert np.linalg.norm(w) == pytest.approx(OMEGA, rel=1e-12)


@FAST
@given(lat_s, angle_s)
def test_polar_tilt_puts_the_whole_earth_rate_on_Z_for_any_spindle_angle(lat_deg, spindle):
    tilt = math.radians(polar_tilt_deg(lat_deg))
    w = earth_rate_platform(math.radians(lat_deg), OMEGA, platform_axes_enu(tilt, spindle, 0.0))
    np.testing.assert_allclose(w, [0.0, 0.0, OMEGA], rtol=0, atol=1e-12 * OMEGA)


def test_polar_tilt_with_a_base_azimuth_error_leaks_earth_rate_into_X_and_Y():
    lat = 37.43
    offset = math.radians(0.12)
    w0 = earth_rate_platform(
        math.radians(lat), OMEGA, platform_axes_enu(math.radians(polar_tilt_deg(lat)), 0.0, offset)
    )
    leak = math.hypot(w0[0], w0[1])
    # To first order the spindle misses the pole by offset * cos(lat) (rad).
    assert leak == pytest.approx(OMEGA * math.cos(math.radians(lat)) * offset, rel=1e-3)


def test_polar_tilt_is_ninety_minus_latitude():
    assert polar_tilt_deg(37.43) == pytest.approx(52.57)
    assert polar_tilt_deg(90.0) == 0.0
    assert polar_tilt_deg(0.0) == 90.0


@FAST
@given(angle_s, offset_s)
def test_level_table_feels_one_g_along_Z_only(spindle, offset):
    f = specific_force_platform(platform_axes_enu(0.0, spindle, offset))
    np.testing.assert_allclose(f, [0.0, 0.0, 1.0], atol=1e-15)


@FAST
@given(tilt_s, angle_s, offset_s)
def test_tilted_table_feels_cos_tilt_on_Z_and_one_g_in_all(tilt, spindle, offset):
    f = specific_force_platform(platform_axes_enu(tilt, spindle, offset))
    assert np.linalg.norm(f) == pytest.approx(1.0, rel=1e-12)
    assert f[2] == pytest.approx(math.cos(tilt), abs=1e-12)


def test_tilt_carries_the_spindle_toward_north():
    axes = platform_axes_enu(math.radians(30.0), 0.0, 0.0)
    east, north, up = axes[2]
    assert east == pytest.approx(0.0, abs=1e-15)
    assert north == pytest.approx(0.5)
    assert up == pytest.approx(math.cos(math.radians(30.0)))
