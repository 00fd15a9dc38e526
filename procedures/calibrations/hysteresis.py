"""``hysteresis``: the gimbal bearings' torque-angle sweep (thesis Ch. V F, Figs. 50-57).

In Mode 3 the autocollimator bias gamma_c, summed into the control channel's output, moves the
platform to about -gamma_c / (control scale): a sinusoidal bias at ``frequency_hz`` (0.4 Hz,
as Fig. 51) is stepped through a ladder of amplitudes from large (Coulomb friction) to small
(a spring). The bias is a DAC: it is updated ``updates_per_cycle`` times a cycle, between ADC
blocks, so every value applied is on the file's time base (channel ``cmd_<axis>``).

The analysis reads only the file: ``procedures.analysis.hysteresis.analyze_file`` (also
``fbs analyze hysteresis FILE --axis X``), whose docstring says how; the plots and the Markdown
are ``procedures.reports.hysteresis``. This module holds the parameters, the sweep steps and the
analysis that turns the result into measurements. Every instrument constant comes from the
rig's data sheet (``rig.calibration``); none is a procedure constant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import partial
from typing import Annotated, Any

from procedures.analysis.hysteresis import AC_AXES, FIGURES, HysteresisResult, analyze_file
from procedures.paramlimits import Each, OneOf, Range, above, at_least, check_limits, sample_rate
from procedures.procedure import Analysis, Context, Figure, Measurement, Procedure, Step
from procedures.reports.hysteresis import (
    markdown,
    plot_describing_function,
    plot_history,
    plot_loops,
    plot_scan,
)
from procedures.rigsetup import InMode3, bring_to_mode3
from procedures.stepresult import StepResult


@dataclass(frozen=True)
class Sweep(StepResult):
    """One amplitude's sinusoidal bias: its bias amplitude (V), its time (rig s) and cycles."""

    amplitude_urad: float
    bias_amplitude_V: float
    t_s: tuple[float, float]
    cycles: int


@dataclass(frozen=True)
class BiasOff(StepResult):
    """The autocollimator bias set back to ``bias_V`` (0)."""

    bias_V: float


#: DESIGN.md section 7, and the angle lag the analysis measured and took out
JSON_KEYS = ("To_Nm", "eta_per_Nm", "stiffness_Nm_per_rad", "angle_lag_ms", "file")


# ---------------------------------------------------------------------------- parameters
@dataclass
class HysteresisParams:
    axis: Annotated[
        str, OneOf(*AC_AXES, note="the others have no instrumentation autocollimator channel")
    ] = "X"
    frequency_hz: Annotated[float, Range(0.001, 100.0, units="Hz")] = 0.4
    #: the ladder, large to small (a large first loop wipes out the bearing's earlier state)
    amplitudes_urad: Annotated[
        list[float], Each(above(0, note="amplitudes are positive"), nonempty=True)
    ] = field(default_factory=lambda: [500.0, 250.0, 100.0, 50.0, 25.0, 10.0, 5.0])
    #: analysed cycles per amplitude, after ``settle_cycles`` left out
    cycles: Annotated[int, at_least(2)] = 6
    settle_cycles: Annotated[int, at_least(0)] = 1
    #: bias DAC updates per cycle; rate_hz / (frequency_hz * updates_per_cycle) must be whole samples
    updates_per_cycle: Annotated[int, at_least(8, note="fewer is too coarse a sine")] = 100
    rate_hz: Annotated[float, sample_rate()] = 400.0
    #: how far the instrumentation angle lags the power-amplifier input (its filters and the
    #: motor's L/R): None (the default) measures it on the record (``dahl.measure_lag``); a
    #: number overrides the measurement, for studies only
    angle_lag_ms: Annotated[float | None, Range(-1000.0, 1000.0, units="ms")] = None
    #: quality limits: fit residual rms / largest loop's torque half-range; relative standard errors
    max_relative_residual: Annotated[float, above(0)] = 0.1
    max_relative_se: Annotated[float, above(0)] = 0.1

    def __post_init__(self) -> None:
        # normalized before the limits are checked: "y" is the Y axis, JSON 500 the number 500.0
        self.axis = str(self.axis).upper()
        self.amplitudes_urad = [float(a) for a in self.amplitudes_urad]
        check_limits(self, "hysteresis")
        # what no one field can declare: limits that tie fields together
        if self.angle_lag_ms is not None and not (abs(self.angle_lag_ms) < 1e3 / self.rate_hz * 20):
            raise ValueError(
                f"hysteresis: angle_lag_ms = {self.angle_lag_ms} must be a few samples at most"
            )
        per_update = self.rate_hz / (self.frequency_hz * self.updates_per_cycle)
        if abs(per_update - round(per_update)) > 1e-9 or round(per_update) < 1:
            raise ValueError(
                f"hysteresis: rate_hz / (frequency_hz * updates_per_cycle) = {per_update:g} samples "
                f"per bias update must be a whole number >= 1"
            )


#: the name the module's functions and tests use
Params = HysteresisParams


class Hysteresis(Procedure[HysteresisParams]):
    name = "hysteresis"
    demo_order = 30
    demo_runs = (("X", ()), ("Y", ()))
    title = "Gimbal bearing torque-angle sweep: Dahl's To and eta (Ch. V F)"
    json_keys = JSON_KEYS
    Params = HysteresisParams
    mode = 3

    def __init__(self, params: HysteresisParams | None = None, **kw) -> None:
        super().__init__(params, **kw)
        p = self.params
        self.axis = p.axis
        self.rate_hz = p.rate_hz
        #: one ADC read per bias update: the DAC changes between reads. Not ``block_s``, the
        #: recording's read size: the longer acquisitions (Mode 3's polls, the bias off) read
        #: in the default blocks, not a few samples at a time
        self.update_s = 1.0 / (p.frequency_hz * p.updates_per_cycle)
        # The torque proxy is millivolts (To ~ 2-4 mV at the amplifier input): +-0.2 V full
        # scale puts 6 uV in a count instead of 0.3 mV at +-10 V.
        self.ranges_V = {f"pa_{p.axis.lower()}": 0.2}

    def channels(self) -> tuple[str, ...]:
        a = self.params.axis.lower()
        return (f"cmd_{a}", f"ac_{a}_inst", f"pa_{a}", f"ac_{a}_ctl")

    def headline(self) -> dict[str, tuple[str, ...]]:
        """The headline figures and their channels (``Procedure.headline``): per axis, as
        ``resolved``; ``angle_lag_ms`` is bookkeeping."""
        return dict.fromkeys(FIGURES, (self.params.axis,))

    def plan(self) -> list[Step[Any]]:
        p = self.params
        per = (p.settle_cycles + p.cycles) / p.frequency_hz
        # The sweep steps run again on --resume (setup=True) rather than being taken over: the
        # fit integrates eq. 5.2 along one continuous recording of the whole ladder, and the
        # bearing's state after an interruption is not the one the earlier steps left.
        sweeps = [
            Step(
                f"{amp:g} urad",
                partial(self.sweep, amplitude_urad=amp),
                expected_s=per,
                setup=True,
                result=Sweep,
            )
            for amp in p.amplitudes_urad
        ]
        return [
            Step("mode 3", bring_to_mode3, expected_s=300.0, setup=True, result=InMode3),
            *sweeps,
            Step(
                "bias off",
                self.bias_off,
                expected_s=1.0 / p.frequency_hz,
                setup=True,
                result=BiasOff,
            ),
        ]

    def sweep(self, ctx: Context, amplitude_urad: float) -> Sweep:
        """``settle_cycles + cycles`` cycles of the sinusoidal bias: theta ~ amplitude sin(w t)."""
        p = self.params
        volts_per_urad = ctx.rig.calibration.autocollimator[p.axis].control_mV_per_urad * 1e-3
        amp_V = amplitude_urad * volts_per_urad
        n = (p.settle_cycles + p.cycles) * p.updates_per_cycle
        t0 = ctx.time_s
        # mid-interval values of the sine; the platform goes to -gamma_c / scale. A stream: one
        # SDO round trip per value, the last read back at the end (``Rig.stream_ac_bias_V``)
        values = (
            -amp_V * math.sin(2 * math.pi * (k + 0.5) / p.updates_per_cycle) for k in range(n)
        )
        ctx.rig.stream_ac_bias_V(p.axis, values, self.update_s, partial(ctx.acquire, keep=False))
        return Sweep(
            amplitude_urad=amplitude_urad,
            bias_amplitude_V=round(amp_V, 6),
            t_s=(round(t0, 4), round(ctx.time_s, 4)),
            cycles=p.settle_cycles + p.cycles,
        )

    def bias_off(self, ctx: Context) -> BiasOff:
        ctx.rig.set_ac_bias_V(self.params.axis, 0.0)
        ctx.acquire(1.0 / self.params.frequency_hz, keep=False)
        return BiasOff(bias_V=0.0)

    def analyze(self, ctx: Context) -> Analysis:
        p = self.params
        res = analyze_file(
            ctx.path,
            p.axis,
            ctx.rig.calibration,
            settle_cycles=p.settle_cycles,
            angle_lag_s=None if p.angle_lag_ms is None else p.angle_lag_ms * 1e-3,
        )
        ms = []
        for key, label, unit, se, note in (
            ("To_Nm", "To", "N m", res.To_se_Nm, "running (Coulomb) friction torque, eq. 5.2; "),
            ("eta_per_Nm", "eta", "1/(N m)", res.eta_se_per_Nm, ""),
            (
                "stiffness_Nm_per_rad",
                "stiffness eta To^2",
                "N m/rad",
                res.stiffness_se_Nm_per_rad,
                "",
            ),
        ):
            e = res.estimates[key]
            ms.append(
                Measurement(
                    label,
                    e.value if e.resolved else None,
                    unit,
                    lo=0.0,
                    stderr=se,
                    note=note
                    + (
                        f"95 % [{e.lo:.5g}, {e.hi:.5g}]" if e.resolved else f"not resolved: {e.why}"
                    ),
                )
            )
        if res.lag is not None:
            lag_note = (
                f"measured at the command's lines ({', '.join(f'{f:.4g}' for f in res.lag.frequencies_hz)} Hz, "
                f"{res.lag.n_cycles} cycles), taken out"
            )
        else:
            lag_note = {
                "given": "given, taken out",
                "fitted": "fitted with To and eta (no line in the command), taken out",
            }.get(res.lag_source, "not measured: the angle used as recorded")
        ms.append(
            Measurement(
                "angle lag behind the power-amplifier input",
                res.angle_lag_s * 1e3,
                "ms",
                stderr=res.angle_lag_se_s * 1e3 if math.isfinite(res.angle_lag_se_s) else None,
                note=lag_note,
            )
        )

        ms += fit_quality(res, p)
        figures = [
            Figure(
                "loops",
                "Bearing torque against angle at each amplitude: synchronous averages and the "
                "Dahl fit (cf. Figs. 51, 53, 54)",
                partial(plot_loops, res=res),
            ),
            Figure(
                "describing-function",
                "Describing function, measured first harmonics and eq. 5.12 (cf. Fig. 57)",
                partial(plot_describing_function, res=res),
            ),
            Figure(
                "history",
                "Angle and torque over the largest loop (cf. Fig. 50)",
                partial(plot_history, res=res),
            ),
            Figure(
                "path-scan",
                "Fit residual, To and eta against the angle path's bandwidth",
                partial(plot_scan, res=res),
            ),
        ]
        return Analysis(res.values(), ms, figures, markdown(res))


def fit_quality(res: HysteresisResult, p: HysteresisParams) -> list[Measurement]:
    """The fit's own checks: its figures' relative errors, its residual, and the ladder's reach
    into both regimes (without both, To and eta are not separable)."""
    xs = [res.theta_o_bar(lp) for lp in res.loops]

    def relative_se(key: str, se: float, value: float) -> float | None:
        # an unresolved figure has no error to judge (a zero-width fit once read "0 ... pass")
        return se / value if res.estimates[key].resolved else None

    return [
        Measurement(
            "To relative standard error",
            relative_se("To_Nm", res.To_se_Nm, res.To_Nm),
            "",
            hi=p.max_relative_se,
        ),
        Measurement(
            "eta relative standard error",
            relative_se("eta_per_Nm", res.eta_se_per_Nm, res.eta_per_Nm),
            "",
            hi=p.max_relative_se,
        ),
        Measurement(
            "fit residual rms / largest loop torque half-range",
            res.relative_residual,
            "",
            hi=p.max_relative_residual,
        ),
        Measurement("largest eta To theta_o (Coulomb regime)", max(xs), "", lo=2.0),
        Measurement("smallest eta To theta_o (spring regime)", min(xs), "", hi=1.0),
        Measurement("angle-path low-pass", res.path_cutoff_hz, "Hz"),
    ]


PROCEDURE = Hysteresis
