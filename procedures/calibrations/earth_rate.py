"""``earth-rate``: torquer scale factor and fixed drift from earth rate (thesis II C.1.a(1), II B.10).

In Mode 3 the caging loops hold every pickoff at null, so each channel's torquer output
voltage cancels the rate about its input axis:

    V_T = -(Omega_i + d) / K_TO                                    (II C.1.a(8); docs/simhw.md 2)

with ``Omega_i`` the earth rate along the input axis and ``d`` the fixed drift. The table is
stepped through azimuths; at each the procedure waits until the torquer outputs have settled
(decided from the data: ``rigsetup.wait_settled``) and averages them. Per channel a least-squares
fit against the component the table geometry predicts gives K_TO, d and the azimuth
misalignment psi0 of the table base:

* X, Y and XRD (input axes horizontal at tilt 0): the spindle through ``n_azimuths`` steps;
* Z is the spindle axis, whose rate turning the spindle does not change: a second orientation
  set, the spindle at ``z_spindle_deg`` (90 deg) and the table tilted through ``z_tilts_deg``.

The fits and their equations are ``procedures.analysis.earth_rate`` (usable without a rig);
the report's table and plot are ``procedures.reports.earth_rate``. This module holds the
parameters, the steps and the analysis that ties them together. Site latitude and earth rate
come from the rig's data sheet (``rig.calibration``), never a procedure constant.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial

import numpy as np

from drivers.calibration import GYRO_CHANNELS
from procedures.analysis.earth_rate import fit_earth_rate
from procedures.reports.earth_rate import markdown, plot_fits
from procedures.rigsetup import bring_to_mode3, mean_and_stderr, wait_settled
from procedures.runner import Analysis, Context, Figure, Measurement, Procedure, Step


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
        stations = [Step(name, partial(self.station, tilt=tilt, spindle=spindle, average_s=avg),
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
                                            partial(plot_fits, fits=fits))],
                        markdown=markdown(fits, stations, self.stations()))


PROCEDURE = EarthRate
