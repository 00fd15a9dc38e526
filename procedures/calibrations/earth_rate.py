"""``earth-rate``: torquer scale factor, fixed and g-sensitive drift from earth rate, a static
multi-position torque-to-balance test (thesis II C.1.a(1), II B.10; IEEE Std 836; CIGTF TTB).

In Mode 3 the caging loops hold every pickoff near null, so each channel's torquer output
voltage balances the rate about its input axis, the drifts and the standing pickoff's
restraint share:

    -K_TO V_T = Omega_i + d + g . f - sigma / (h/k)                 (II C.1.a(8); docs/simhw.md 2)

The table visits every spindle angle of ``n_spindle`` at each tilt of ``tilts_deg``, the
spindle turning one way at one tilt and back at the next (so a slow trend cannot pose as a
spindle-angle term). Tilting moves the earth rate and the specific force along every platform
axis differently: the horizontal channels' scale factor comes from the spindle turning their
input axes through the earth rate's horizontal component, Z's from the tilt, and the tilts
separate each channel's fixed drift from its g-sensitive drifts along x, y and z, which a
tilt-0 sweep cannot (there "fixed drift" would be fixed plus the g-drift along the vertical).
At each station the procedure waits until the torquer outputs have settled (decided from the
data: ``rigsetup.wait_settled``) and averages the torquer and pickoff outputs.

The fits, their intervals and the resolved verdicts are ``procedures.analysis.earth_rate``
(usable without a rig); the report's table and plot are ``procedures.reports.earth_rate``. Site
latitude, earth rate, h/k and the nominal pickoff scale factors come from the rig's data sheet
(``rig.calibration``), never a procedure constant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import partial
from typing import Annotated, Any

import numpy as np

from drivers.rig_datasheet import GYRO_CHANNELS
from procedures.analysis.earth_rate import G_AXES, Station, fit_earth_rate
from procedures.analysis.intervals import add_figure
from procedures.paramlimits import Each, Range, above, at_least, check_limits, fraction, sample_rate
from procedures.params import pickoff_scale_rel_half_width, prior_values
from procedures.procedure import Analysis, Context, Figure, Measurement, Procedure, Step
from procedures.reports.earth_rate import markdown, plot_fits
from procedures.rigsetup import InMode3, bring_to_mode3, mean_and_stderr, wait_settled
from procedures.stepresult import StepResult


@dataclass(frozen=True)
class TableAt(StepResult):
    """Where the table is, read back (deg)."""

    tilt: float
    spindle: float


@dataclass
class EarthRateParams:
    #: table tilts (deg) in the order visited; at least three different ones, some above 0,
    #: separate the drifts. Not monotonic, so a slow trend over the run is not a tilt term
    #: (visited 0, 45, 90 the fixed drift and the g-drift along z correlate by -0.97).
    tilts_deg: Annotated[
        list[float], Each(Range(0.0, 90.0, units="deg", note="the table's tilt range"))
    ] = field(default_factory=lambda: [0.0, 90.0, 45.0])
    #: spindle angles per tilt, equally spaced
    n_spindle: Annotated[int, Range(4, 36, note="the spindle angles per tilt")] = 8
    average_s: Annotated[float, above(0)] = 60.0
    settle_tol_V: Annotated[float, above(0, units="V")] = 3e-4
    settle_window_s: Annotated[float, above(0)] = 40.0
    #: the caging loops (omega_n 0.1 rad/s) and their coupling through the float's viscous
    #: coupling leave a slow tail of a few mV for a minute or two after a step of the table,
    #: below what the noisy trend test can see: never average sooner than this
    settle_min_s: Annotated[float, at_least(0)] = 120.0
    settle_timeout_s: Annotated[float, above(0)] = 900.0
    rate_hz: Annotated[float, sample_rate()] = 50.0
    #: the gyros' bias instability (urad/s) from a data sheet, if known: the fixed drift's interval
    #: then carries a run's wander about the long-term fixed drift. An earlier drift run's figure
    #: (``--prior``, the same --out) is used before it. Without either, the interval is this
    #: run's bias and says so.
    bias_instability_urad_per_s: Annotated[
        float | None, Range(0.0, 10.0, hi_open=True, units="urad/s")
    ] = None
    #: limits: K_TO within this fraction of the rig's nominal (data sheet) value, fit residual rms
    kto_tolerance: Annotated[float, fraction(note="of the nominal K_TO")] = 0.2
    max_residual_V: Annotated[float, above(0, units="V")] = 5e-3

    def __post_init__(self) -> None:
        check_limits(self, "earth-rate")
        # what no one field can declare: the stations must separate the fit's unknowns
        if len(set(self.tilts_deg)) < 3 or max(self.tilts_deg) <= 0.0:
            raise ValueError(
                f"earth-rate: tilts_deg {self.tilts_deg} needs at least 3 different tilts, some above 0 "
                f"(the fixed and g-sensitive drifts and Z's scale factor are separated by tilting)"
            )
        if len(self.tilts_deg) * int(self.n_spindle) < 12:
            raise ValueError(
                f"earth-rate: {len(self.tilts_deg)} tilts x {self.n_spindle} spindle angles is under 12 "
                f"stations (the fit has 7 unknowns and needs residuals for its intervals)"
            )


def _channel_column(ch: str) -> str:
    return f"torq_{ch.lower()}"


#: the name the module's functions and tests use
Params = EarthRateParams


class EarthRate(Procedure[EarthRateParams]):
    name = "earth-rate"
    demo_order = 10
    title = "Torquer scale factor and drift from earth rate (II C.1.a(1))"
    json_keys = (
        "K_TO_urad_per_s_per_V",
        "drift_urad_per_s",
        "g_drift_x_urad_per_s_per_g",
        "g_drift_y_urad_per_s_per_g",
        "g_drift_z_urad_per_s_per_g",
        "file",
    )
    Params = EarthRateParams
    mode = 3
    block_s = 1.0

    def __init__(self, params: EarthRateParams | None = None, **kw) -> None:
        super().__init__(params, **kw)
        self.rate_hz = self.params.rate_hz

    def channels(self) -> tuple[str, ...]:
        return tuple(_channel_column(c) for c in GYRO_CHANNELS) + tuple(
            f"gyro_{c.lower()}" for c in GYRO_CHANNELS
        )

    def headline(self) -> dict[str, tuple[str, ...]]:
        """The headline figures and their channels (``Procedure.headline``)."""
        return dict.fromkeys((k for k in self.json_keys if k != "file"), GYRO_CHANNELS)

    def stations(self) -> list[tuple[str, float, float, float]]:
        """(name, tilt, spindle, averaging time) in the order visited: every spindle angle at
        each tilt, the spindle turning back at every other tilt."""
        p = self.params
        spindles = list(np.arange(int(p.n_spindle)) * 360.0 / int(p.n_spindle))
        out = []
        for i, t in enumerate(p.tilts_deg):
            for psi in spindles if i % 2 == 0 else spindles[::-1]:
                out.append(
                    (f"tilt {t:g} deg, spindle {psi:g} deg", float(t), float(psi), p.average_s)
                )
        return out

    def plan(self) -> list[Step[Any]]:
        stations = [
            Step(
                name,
                partial(self.station, tilt=tilt, spindle=spindle, average_s=avg),
                expected_s=avg + self.params.settle_min_s + 10.0,
                result=Station,
            )
            for name, tilt, spindle, avg in self.stations()
        ]
        return [
            Step("mode 3", bring_to_mode3, expected_s=300.0, setup=True, result=InMode3),
            *stations,
            Step("table home", self.home, expected_s=5.0, setup=True, result=TableAt),
        ]

    def station(self, ctx: Context, tilt: float, spindle: float, average_s: float) -> Station:
        p = self.params
        pos = ctx.rig.move_table(
            tilt_deg=tilt, spindle_deg=spindle
        )  # a manual table asks the operator
        cols = [ctx.column(_channel_column(c)) for c in GYRO_CHANNELS]
        pick = [ctx.column(f"gyro_{c.lower()}") for c in GYRO_CHANNELS]
        settled = wait_settled(
            ctx,
            cols,
            tol_V=p.settle_tol_V,
            window_s=p.settle_window_s,
            min_s=p.settle_min_s,
            timeout_s=p.settle_timeout_s,
        )
        t0 = ctx.time_s
        data = ctx.acquire(average_s)
        mean, se = mean_and_stderr(data[:, cols])
        pmean, _ = mean_and_stderr(data[:, pick])
        return Station(
            tilt=pos.tilt_deg,
            spindle=pos.spindle_deg,
            t=(round(t0, 3), round(ctx.time_s, 3)),
            settle_s=round(settled.waited_s, 1),
            V={c: float(m) for c, m in zip(GYRO_CHANNELS, mean)},
            se={c: float(s) for c, s in zip(GYRO_CHANNELS, se)},
            pickoff_V={c: float(m) for c, m in zip(GYRO_CHANNELS, pmean)},
        )

    def home(self, ctx: Context) -> TableAt:
        pos = ctx.rig.move_table(tilt_deg=0.0, spindle_deg=0.0)
        return TableAt(tilt=pos.tilt_deg, spindle=pos.spindle_deg)

    # ------------------------------------------------------------------ analysis
    def analyze(self, ctx: Context) -> Analysis:
        cal = ctx.rig.calibration
        stations = [ctx.result(st[0], Station) for st in self.stations()]
        p = self.params
        # K_g for the standing pickoff: a stopwatch run's if at hand, else the data sheet's
        kg, kg_from = prior_values(
            self.prior, "stopwatch", "K_g_mV_per_urad", GYRO_CHANNELS, cal.pickoff_scale_mV_per_urad
        )
        kg_rel = {
            ch: pickoff_scale_rel_half_width(self.prior, kg_from[ch], ch, kg[ch])
            for ch in GYRO_CHANNELS
        }
        given = p.bias_instability_urad_per_s or 0.0
        bi, self.instability_sources = prior_values(
            self.prior,
            "drift",
            "bias_instability_urad_per_s",
            GYRO_CHANNELS,
            {ch: given for ch in GYRO_CHANNELS},
        )
        fits = fit_earth_rate(
            stations,
            latitude_deg=cal.latitude_deg,
            earth_rate_rad_per_s=cal.earth_rate_rad_per_s,
            restraint_s=cal.restraint_time_constant_s,
            pickoff_mV_per_urad=kg,
            instability_urad_per_s=bi,
            pickoff_rel_uncertainty=kg_rel,
        )
        ms: list[Measurement] = []
        for ch, f in fits.items():
            nominal = cal.torquer_scale_urad_per_s_per_V[ch]
            ms.append(
                Measurement(
                    f"K_TO {ch}",
                    f.kto.value,
                    "urad/s/V",
                    nominal * (1 - p.kto_tolerance),
                    nominal * (1 + p.kto_tolerance),
                    f.kto.half_width / 1.96,
                    note=f"95 % [{f.kto.lo:.6g}, {f.kto.hi:.6g}]",
                )
            )
            for label, e, unit in (
                ("drift", f.drift, "urad/s"),
                *((f"g-drift along {a}", f.g_drift[a], "urad/s/g") for a in G_AXES),
            ):
                ms.append(
                    Measurement(
                        f"{label} {ch}",
                        e.value if e.resolved else None,
                        unit,
                        stderr=e.half_width / 1.96 if math.isfinite(e.half_width) else None,
                        note=(
                            f"95 % [{e.lo:.4g}, {e.hi:.4g}]"
                            if e.resolved
                            else f"not resolved: {e.why}"
                            + (f"; 95 % [{e.lo:.4g}, {e.hi:.4g}]" if math.isfinite(e.lo) else "")
                        ),
                    )
                )
            if f.psi0_deg is not None:
                ms.append(Measurement(f"table azimuth misalignment psi0 ({ch})", f.psi0_deg, "deg"))
            ms.append(
                Measurement(f"fit residual rms {ch}", f.residual_rms_V, "V", hi=p.max_residual_V)
            )
        values: dict = {}
        add_figure(values, "K_TO_urad_per_s_per_V", {ch: f.kto for ch, f in fits.items()})
        add_figure(values, "drift_urad_per_s", {ch: f.drift for ch, f in fits.items()})
        for a in G_AXES:
            add_figure(
                values,
                f"g_drift_{a}_urad_per_s_per_g",
                {ch: f.g_drift[a] for ch, f in fits.items()},
            )
        return Analysis(
            values,
            ms,
            [
                Figure(
                    "fit",
                    "Torquer output at each station (tilt, spindle) against the multi-position fit",
                    partial(plot_fits, fits=fits),
                )
            ],
            markdown=markdown(fits, stations, self.stations()),
        )


PROCEDURE = EarthRate
