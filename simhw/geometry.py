"""Rotary table geometry: earth rate and gravity in platform axes (Ch. II C.4.b).

Frames: local ENU (east, north, up). The table base sits with its azimuth off north by
``base_azimuth_offset``; its east-west shaft tilts the spindle from vertical toward north by
``tilt``; the spindle turns the platform by ``spindle`` about the spindle axis, which is the
platform Z (outer gimbal) axis. With the gimbals at null the platform axes are the table-head
axes: at tilt 0, platform X points ``spindle - offset`` from north toward west, so the earth
rate along X is Omega cos(lat) cos(spindle - offset).
"""

from __future__ import annotations

import math

import numpy as np


def platform_axes_enu(tilt_rad: float, spindle_rad: float, offset_rad: float) -> np.ndarray:
    """3x3 matrix whose rows are the platform X, Y, Z unit vectors in ENU."""
    east, north, up = np.eye(3)
    west = -east
    a = -offset_rad
    xb = north * math.cos(a) + west * math.sin(a)
    yb = -north * math.sin(a) + west * math.cos(a)
    zb = up
    # Tilt about the base's east-west shaft (yb) carries the spindle toward north (xb).
    zt = zb * math.cos(tilt_rad) + xb * math.sin(tilt_rad)
    xt = xb * math.cos(tilt_rad) - zb * math.sin(tilt_rad)
    yt = yb
    xp = xt * math.cos(spindle_rad) + yt * math.sin(spindle_rad)
    yp = -xt * math.sin(spindle_rad) + yt * math.cos(spindle_rad)
    return np.vstack([xp, yp, zt])


def earth_rate_platform(latitude_rad: float, earth_rate: float, axes: np.ndarray) -> np.ndarray:
    """Earth rate (rad/s) resolved on the platform X, Y, Z axes."""
    omega_enu = earth_rate * np.array([0.0, math.cos(latitude_rad), math.sin(latitude_rad)])
    return axes @ omega_enu


def specific_force_platform(axes: np.ndarray) -> np.ndarray:
    """Specific force (in g) on the platform axes: +1 g up, the reaction of the support."""
    return axes @ np.array([0.0, 0.0, 1.0])


def polar_tilt_deg(latitude_deg: float) -> float:
    """Table tilt that points the spindle (platform Z) at the celestial pole."""
    return 90.0 - latitude_deg
