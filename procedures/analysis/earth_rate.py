"""The earth-rate fits: torquer scale factor K_TO, fixed drift d and the table base's azimuth
misalignment psi0 from the settled torquer outputs at known table orientations (thesis
II C.1.a(1), II B.10). Plain arrays and station dicts in, ``ChannelFit`` out; no rig. The
procedure that takes the stations is ``procedures.calibrations.earth_rate`` (its docstring has
the measurement); the report's table and plot are ``procedures.reports.earth_rate``.

Per channel, with ``V_T = -(Omega_i + d) / K_TO`` (II C.1.a(8)):

* X, Y and XRD (input axes horizontal at tilt 0): spindle psi through ``n_azimuths`` steps,
  ``Omega_x = Omega_H cos(psi - psi0)``, ``Omega_y = -Omega_H sin(psi - psi0)``,
  ``Omega_H = Omega cos(latitude)``. Linear in (a, b, c) of ``a cos psi + b sin psi + c``;
  K_TO = Omega_H / hypot(a, b).
* Z is the spindle axis: turning the spindle does not change its rate. It gets a second
  orientation set: the spindle at 90 deg (platform X on the horizontal tilt shaft, so no
  X-sensitive g-drift changes) and the table tilted through ``z_tilts_deg``;
  ``Omega_z = Omega (sin(lat) cos(t) + cos(lat) cos(psi0) sin(t))`` spans
  Omega sin(lat) .. Omega. Linear in (alpha, beta) of ``alpha Omega_z + beta``.

Standard errors come from the fit residuals (delta method for K_TO and psi0). Site latitude
and earth rate are arguments (the rig's data sheet), never constants here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from drivers.calibration import GYRO_CHANNELS

HORIZONTAL = ("X", "Y", "XRD")
URAD = 1e-6


@dataclass
class ChannelFit:
    channel: str
    kto_urad_per_s_per_V: float
    kto_se: float
    drift_urad_per_s: float
    drift_se: float
    psi0_deg: float | None
    psi0_se: float | None
    x_deg: np.ndarray            # the swept angle (spindle or tilt)
    volts: np.ndarray
    predicted: np.ndarray
    residual_rms_V: float
    swept: str


def _lstsq(design: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Coefficients, their covariance from the residual variance, and the residuals."""
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    resid = y - design @ coef
    dof = max(1, len(y) - design.shape[1])
    cov = np.linalg.inv(design.T @ design) * (resid @ resid) / dof
    return coef, cov, resid


def _delta_se(gradient: np.ndarray, cov: np.ndarray) -> float:
    """Standard error of a function of the coefficients by the delta method."""
    return float(math.sqrt(max(0.0, gradient @ cov @ gradient)))


def _trend(order: np.ndarray | None, n: int) -> np.ndarray:
    """The drift-trend regressor: the stations' visiting order, centred (none if not given).
    The order, not the time, so that stations taken over by ``--resume`` from another file
    (another time base) still line up; the stations of a group take about equal times."""
    if order is None:
        return np.zeros((n, 0))
    k = np.asarray(order, float)
    return (k - k.mean())[:, None]


def fit_horizontal(ch: str, psi_deg: np.ndarray, volts: np.ndarray, omega_h: float,
                   order: np.ndarray | None = None) -> ChannelFit:
    """Fit ``V = a cos psi + b sin psi + c [+ e t]`` and map to K_TO, d, psi0 (module docstring).
    The optional term ``e t`` (t the visiting order) keeps a slow drift trend out of a, b and c."""
    psi = np.radians(psi_deg)
    design = np.column_stack([np.cos(psi), np.sin(psi), np.ones_like(psi), _trend(order, len(psi))])
    coef, cov, resid = _lstsq(design, volts)
    a, b, c = coef[:3]
    cov = cov[:3, :3]
    amp = math.hypot(a, b)                              # = Omega_H / K_TO
    # Y: V = (Omega_H sin(psi - psi0) - d) / K_TO; X, XRD: V = -(Omega_H cos(psi - psi0) + d) / K_TO
    psi0 = math.atan2(-a, b) if ch == "Y" else math.atan2(-b, -a)
    d_psi0 = np.array([-b, a, 0.0]) / amp ** 2          # the same gradient for both forms
    kto = omega_h / amp
    d_kto = -omega_h / amp ** 3 * np.array([a, b, 0.0])
    drift = -c * kto
    d_drift = -c * d_kto + np.array([0.0, 0.0, -kto])
    return ChannelFit(ch, kto / URAD, _delta_se(d_kto, cov) / URAD, drift / URAD,
                      _delta_se(d_drift, cov) / URAD, math.degrees(psi0), math.degrees(_delta_se(d_psi0, cov)),
                      np.asarray(psi_deg), volts, volts - resid, float(np.sqrt(np.mean(resid ** 2))), "spindle")


def omega_z(tilt_deg: np.ndarray, latitude_deg: float, earth_rate: float, psi0_deg: float = 0.0) -> np.ndarray:
    """Earth rate along the spindle (platform Z) at table tilt t (simhw.geometry's convention)."""
    t, lat = np.radians(tilt_deg), math.radians(latitude_deg)
    return earth_rate * (math.sin(lat) * np.cos(t) + math.cos(lat) * math.cos(math.radians(psi0_deg)) * np.sin(t))


def fit_vertical(ch: str, tilt_deg: np.ndarray, volts: np.ndarray, omega: np.ndarray,
                 order: np.ndarray | None = None) -> ChannelFit:
    """Fit ``V = alpha Omega_z + beta [+ e t]``: K_TO = -1/alpha, d = -beta K_TO."""
    design = np.column_stack([omega, np.ones_like(omega), _trend(order, len(omega))])
    coef, cov, resid = _lstsq(design, volts)
    alpha, beta = coef[:2]
    cov = cov[:2, :2]
    kto = -1.0 / alpha
    d_kto = np.array([1.0 / alpha ** 2, 0.0])
    drift = -beta * kto
    d_drift = np.array([-beta / alpha ** 2, -kto])
    return ChannelFit(ch, kto / URAD, _delta_se(d_kto, cov) / URAD, drift / URAD,
                      _delta_se(d_drift, cov) / URAD, None, None, np.asarray(tilt_deg), volts, volts - resid,
                      float(np.sqrt(np.mean(resid ** 2))), "tilt")


def fit_earth_rate(azimuth_stations: list[dict], tilt_stations: list[dict], *, latitude_deg: float,
                   earth_rate_rad_per_s: float) -> dict[str, ChannelFit]:
    """Every channel's fit from the stations' results (``"spindle"``, ``"tilt"`` in deg and the
    settled means ``"V"`` per channel), in visiting order: the azimuth stations for X, Y and
    XRD, the tilt stations for Z (at the horizontal channels' mean psi0)."""
    omega_h = earth_rate_rad_per_s * math.cos(math.radians(latitude_deg))
    psi = np.array([s["spindle"] for s in azimuth_stations])
    fits = {ch: fit_horizontal(ch, psi, np.array([s["V"][ch] for s in azimuth_stations]), omega_h,
                               np.arange(len(psi)))
            for ch in HORIZONTAL}
    psi0 = float(np.mean([fits[c].psi0_deg for c in HORIZONTAL]))
    tilt = np.array([s["tilt"] for s in tilt_stations])
    fits["Z"] = fit_vertical("Z", tilt, np.array([s["V"]["Z"] for s in tilt_stations]),
                             omega_z(tilt, latitude_deg, earth_rate_rad_per_s, psi0),
                             np.arange(len(tilt)))
    return {ch: fits[ch] for ch in GYRO_CHANNELS}
