"""``earth-rate``: torquer scale factor and fixed drift from earth rate (thesis II C.1.a(1), II B.10).

In Mode 3 the caging loops hold every pickoff at null, so each channel's torquer output
voltage cancels the rate about its input axis:

    V_T = -(Omega_i + d) / K_TO                                    (II C.1.a(8); docs/simhw.md 2)

with ``Omega_i`` the earth rate along the input axis and ``d`` the fixed drift. The table is
stepped through azimuths; at each the procedure waits until the torquer outputs have settled
(decided from the data: ``rigsetup.wait_settled``) and averages them. Per channel a least-squares
fit against the component the table geometry predicts gives K_TO, d and the azimuth
misalignment psi0 of the table base:

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
and earth rate come from the rig's data sheet (``rig.calibration``), never a procedure constant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from drivers.calibration import GYRO_CHANNELS
from procedures.reports.plotting import new_figure, save_figure
from procedures.reports.report import fmt
from procedures.rigsetup import bring_to_mode3, mean_and_stderr, wait_settled
from procedures.runner import Analysis, Context, Figure, Measurement, Procedure, Step

HORIZONTAL = ("X", "Y", "XRD")
URAD = 1e-6


@dataclass
class EarthRateParams:
    n_azimuths: int = 12
    #: table tilts (deg) for the Z channel, spindle at ``z_spindle_deg``
    #: visited up and back down, so a slow drift trend cannot pose as scale factor
    z_tilts_deg: list[float] = field(default_factory=lambda: [0.0, 22.5, 45.0, 67.5, 90.0, 67.5, 45.0, 22.5, 0.0])
    z_spindle_deg: float = 90.0
    average_s: float = 40.0
    #: Z's torquer output is noisier (the X-Z gyro's viscous coupling passes the redundant
    #: channel's fast proportional caging loop into it) and its rate spans only
    #: Omega sin(lat)..Omega: it is averaged longer
    z_average_s: float = 160.0
    settle_tol_V: float = 3e-4
    settle_window_s: float = 40.0
    #: the caging loops (omega_n 0.1 rad/s) and their coupling through the float's viscous
    #: coupling leave a slow tail of a few mV for a minute or two after a 30-degree step,
    #: below what the noisy trend test can see: never average sooner than this
    settle_min_s: float = 120.0
    settle_timeout_s: float = 900.0
    rate_hz: float = 50.0
    #: limits: K_TO within this fraction of the rig's nominal (data sheet) value, fit residual rms
    kto_tolerance: float = 0.2
    max_residual_V: float = 5e-3

    def __post_init__(self) -> None:
        if not 5 <= int(self.n_azimuths) <= 72:
            raise ValueError(f"earth-rate: n_azimuths = {self.n_azimuths} must be 5..72 (the fit has 4 unknowns "
                             f"and needs residuals for its standard errors)")
        if len(self.z_tilts_deg) < 4:
            raise ValueError(f"earth-rate: z_tilts_deg {self.z_tilts_deg} needs at least 4 tilts (3 unknowns)")
        for t in self.z_tilts_deg:
            if not 0.0 <= t <= 90.0:
                raise ValueError(f"earth-rate: tilt {t} deg is outside the table's 0..90 deg")
        if min(self.average_s, self.z_average_s, self.rate_hz) <= 0:
            raise ValueError("earth-rate: average_s, z_average_s and rate_hz must be > 0")


def _channel_column(ch: str) -> str:
    return f"torq_{ch.lower()}"


#: the name the module's functions and tests use
Params = EarthRateParams


class EarthRate(Procedure[EarthRateParams]):
    name = "earth-rate"
    title = "Torquer scale factor and drift from earth rate (II C.1.a(1))"
    json_keys = ("K_TO_urad_per_s_per_V", "drift_urad_per_s", "file")
    Params = EarthRateParams
    mode = 3
    block_s = 1.0

    def __init__(self, params: EarthRateParams | None = None, **kw) -> None:
        super().__init__(params, **kw)
        self.rate_hz = self.params.rate_hz

    def channels(self) -> tuple[str, ...]:
        return tuple(_channel_column(c) for c in GYRO_CHANNELS) + tuple(f"gyro_{c.lower()}" for c in GYRO_CHANNELS)

    def stations(self) -> list[tuple[str, float, float, float]]:
        """(name, tilt, spindle, averaging time) in the order visited."""
        p = self.params
        out = [(f"azimuth {psi:g} deg", 0.0, psi, p.average_s)
               for psi in np.arange(p.n_azimuths) * 360.0 / p.n_azimuths]
        out += [(f"tilt {t:g} deg ({i + 1})", float(t), p.z_spindle_deg, p.z_average_s)
                for i, t in enumerate(p.z_tilts_deg)]
        return out

    def plan(self) -> list[Step]:
        stations = [Step(name, lambda c, t=tilt, s=spindle, a=avg: self.station(c, t, s, a),
                         expected_s=avg + self.params.settle_min_s + 10.0)
                    for name, tilt, spindle, avg in self.stations()]
        return [Step("mode 3", bring_to_mode3, expected_s=300.0, setup=True), *stations,
                Step("table home", self.home, expected_s=5.0, setup=True)]

    def station(self, ctx: Context, tilt: float, spindle: float, average_s: float) -> dict:
        p = self.params
        pos = ctx.rig.move_table(tilt_deg=tilt, spindle_deg=spindle)  # a manual table asks the operator
        cols = [ctx.column(_channel_column(c)) for c in GYRO_CHANNELS]
        settled = wait_settled(ctx, cols, tol_V=p.settle_tol_V, window_s=p.settle_window_s,
                               min_s=p.settle_min_s, timeout_s=p.settle_timeout_s)
        t0 = ctx.time_s
        data = ctx.acquire(average_s)[:, cols]
        mean, se = mean_and_stderr(data)
        return {"tilt": pos.tilt_deg, "spindle": pos.spindle_deg, "t": [round(t0, 3), round(ctx.time_s, 3)],
                "settle_s": round(settled.waited_s, 1),
                "V": {c: float(m) for c, m in zip(GYRO_CHANNELS, mean)},
                "se": {c: float(s) for c, s in zip(GYRO_CHANNELS, se)}}

    def home(self, ctx: Context) -> dict:
        pos = ctx.rig.move_table(tilt_deg=0.0, spindle_deg=0.0)
        return {"tilt": pos.tilt_deg, "spindle": pos.spindle_deg}

    # ------------------------------------------------------------------ analysis
    def analyze(self, ctx: Context) -> Analysis:
        cal = ctx.rig.calibration
        stations = [ctx.results[st[0]] for st in self.stations()]
        n_az = self.params.n_azimuths
        fits = fit_earth_rate(stations[:n_az], stations[n_az:], latitude_deg=cal.latitude_deg,
                              earth_rate_rad_per_s=cal.earth_rate_rad_per_s)
        p = self.params
        ms: list[Measurement] = []
        for ch, f in fits.items():
            nominal = cal.torquer_scale_urad_per_s_per_V[ch]
            ms.append(Measurement(f"K_TO {ch}", f.kto_urad_per_s_per_V, "urad/s/V", nominal * (1 - p.kto_tolerance),
                                  nominal * (1 + p.kto_tolerance), f.kto_se))
            ms.append(Measurement(f"drift {ch}", f.drift_urad_per_s, "urad/s", stderr=f.drift_se))
            if f.psi0_deg is not None:
                ms.append(Measurement(f"table azimuth misalignment psi0 ({ch})", f.psi0_deg, "deg", stderr=f.psi0_se))
            ms.append(Measurement(f"fit residual rms {ch}", f.residual_rms_V, "V", hi=p.max_residual_V))
        values = {"K_TO_urad_per_s_per_V": {ch: f.kto_urad_per_s_per_V for ch, f in fits.items()},
                  "drift_urad_per_s": {ch: f.drift_urad_per_s for ch, f in fits.items()}}
        return Analysis(values, ms, [Figure("fit", "Torquer output against table azimuth (X, Y, XRD) and tilt (Z), "
                                            "with the least-squares earth-rate fit",
                                            lambda path: plot_fits(path, fits))],
                        markdown=_markdown(fits, stations, self.stations()))


# ---------------------------------------------------------------------------- fitting
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


# ---------------------------------------------------------------------------- report
def plot_fits(path: Path, fits: dict[str, ChannelFit]) -> None:
    fig, axes = new_figure(2, 2, figsize=(10, 7))
    for ax, (ch, f) in zip(axes.flat, fits.items()):
        order = np.argsort(f.x_deg)
        ax.plot(f.x_deg[order], f.volts[order], "o", label="settled mean")
        ax.plot(f.x_deg[order], f.predicted[order], "-", label="fit")
        ax.set_title(f"{ch}: K_TO {f.kto_urad_per_s_per_V:.4g} ± {f.kto_se:.2g} urad/s/V")
        ax.set_xlabel(f"table {f.swept} angle (deg)")
        ax.set_ylabel(f"torq_{ch.lower()} (V)")
        ax.grid(True, alpha=0.4)
        ax.legend(fontsize=8)
    save_figure(fig, path)


def _markdown(fits: dict[str, ChannelFit], stations: list[dict], names) -> str:
    lines = ["## Fit", "", "| channel | K_TO (urad/s/V) | drift (urad/s) | psi0 (deg) | residual rms (mV) | swept |",
             "|---|---|---|---|---|---|"]
    for ch, f in fits.items():
        psi0 = "-" if f.psi0_deg is None else f"{f.psi0_deg:.4f} ± {f.psi0_se:.4f}"
        lines.append(f"| {ch} | {f.kto_urad_per_s_per_V:.5g} ± {f.kto_se:.2g} | {f.drift_urad_per_s:.4g} ± "
                     f"{f.drift_se:.2g} | {psi0} | {f.residual_rms_V * 1e3:.3f} | {f.swept} |")
    lines += ["", "Each fit has a term linear in the stations' visiting order as well, so a slow drift trend over the run "
              "does not bias the scale factor.", "",
              "Z is the spindle axis, so its rate does not change with the spindle angle; it was calibrated "
              "with the spindle at 90 deg and the table tilted (module docstring).", "",
              "## Stations", "", "| station | tilt | spindle | settled after (s) | " +
              " | ".join(f"torq {c} (V)" for c in GYRO_CHANNELS) + " |", "|---|---|---|---|" + "---|" * 4]
    for (name, *_), s in zip(names, stations):
        lines.append(f"| {name} | {fmt(s['tilt'])} | {fmt(s['spindle'])} | {s['settle_s']} | "
                     + " | ".join(f"{s['V'][c]:+.5f}" for c in GYRO_CHANNELS) + " |")
    return "\n".join(lines)


PROCEDURE = EarthRate
