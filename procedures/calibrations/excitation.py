"""``excitation``: coherent measurement with an injected command torque (thesis Ch. V C-D,
Figs. 35-41 and 52).

In Mode 3 (autocollimator stabilization) the procedure records

1. a quiet piece, nothing injected: the compensation network's H1 from its recorded input (the
   control channel ``ac_<a>_ctl``) and output (the amplifier input ``pa_<a>``), as the thesis
   did for Fig. 40: the network driven by the loop's own noise. It is plotted, and starts the
   network's fit; the corners reported are fitted inside the excited loop (3.), whose lines are
   in steady state: with 8 s Welch segments the network's 6.7 s pole leaves output of input
   from before each segment, which read w1 +46 % with an interval wholly above the truth, and
   w3 and w4 0.3-0.6 % off with intervals a tenth of that wide (issue 38);
2. a short probe with band-limited noise as V_Td at a small level, from which the level that
   moves the platform by ``target_urad`` rms is found (the loop's response is linear in V_Td;
   the level is then cut so that no channel exceeds ``max_range_fraction`` of its ADC range and
   V_Td's peak stays inside the DAC);
3. the excited piece: a multisine (every frequency k / ``period_s`` in ``band_lo_hz``-
   ``band_hi_hz``, equal amplitudes, random phases; one period repeated), updated ``update_hz``
   times a second between ADC blocks, so every value applied is on the file's time base as
   ``cmd_<a>``, at that level. Whole periods are analysed without a window, so the excited
   lines have no leakage (``transfer.periodic_blocks``).

The analysis (``procedures.analysis.transfer``, whose docstring says how) gives the network's
corners (eq. 3.28, from v_c = pa - K_d V_Td per its input through V_Td) and the platform's
inertia, damping and bearing stiffness (eqs. 3.23-3.27) from the response of the
autocollimator to the amplifier input measured through V_Td; each with a jackknife 95 %
interval. Stiffness and damping carry the excited motion's rms (``excitation_amplitude_urad``)
and whether the data show they depend on it (``amplitude_dependent``): on a Dahl bearing they
are its describing function at that motion, and the damping, which then depends on frequency,
is not resolved. Neither uses the data sheet's inertia or the design corners:
those appear in the report only, beside the measured values. The amplifier, motor and sensor
constants are the data sheet's (``rig.calibration``).

Coherent and incoherent parts of each sensor's spectrum (Ch. V C): with gamma^2 the coherence
of the sensor with V_Td, gamma^2 S is what the platform's excited motion put there, and
(1 - gamma^2) S the rest: the sensor's own noise and the platform's unexcited motion.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Annotated, Any

import numpy as np

from daq.spectral import coherence, equivalent_dof, n_segments, welch_csd_matrix
from drivers.rig_datasheet import AutocollimatorConstants, RigCalibration
from procedures.analysis.intervals import add_figure
from procedures.analysis.roots import (
    IN_LOOP_GAIN_ALLOWANCE,
    ClosedLoop,
    GyroCaging,
    LoopParts,
    close_loop,
    sensor_estimate,
    sensor_gain,
)
from procedures.analysis.transfer import (
    DESIGN_NETWORK,
    NETWORK_CORNERS,
    BlockCsd,
    ModelFit,
    Response,
    TransferError,
    block_csd,
    fit_network,
    fit_platform,
    network_in_loop,
    network_response,
    periodic_blocks,
    response,
    sensor_filter,
    sensor_scale_V_per_rad,
    unbiased_coherence,
)
from procedures.paramlimits import (
    MAX_PROCEDURE_RATE_HZ,
    OneOf,
    Range,
    above,
    at_least,
    check_limits,
    sample_rate,
)
from procedures.params import pickoff_scale_rel_half_width, prior_values
from procedures.procedure import (
    Analysis,
    Context,
    Figure,
    Measurement,
    Procedure,
    ProcedureError,
    Step,
)
from procedures.reports.excitation import markdown, plot_response
from procedures.reports.thesis import closed_loop_roots as thesis_roots
from procedures.rigsetup import InMode3, ModeSet, back_to_mode3, bring_to_mode3, enter_gyro_mode
from procedures.stepresult import Recorded, StepResult, Waited


@dataclass(frozen=True)
class ProbeTry(StepResult):
    """One probe level (V_Td rms) and the platform motion it made (urad rms)."""

    V_rms: float
    moved_urad_rms: float


@dataclass(frozen=True)
class Probe(StepResult):
    """The probe's outcome: the excitation level chosen (``level_V_rms``), the range that
    limits it, and the probes that found it."""

    probe_V_rms: float
    probe_motion_urad_rms: float
    quiet_urad_rms: float
    probes: tuple[ProbeTry, ...]
    target_urad_rms: float
    level_V_rms: float
    limited_by: str
    expected_motion_urad_rms: float


@dataclass(frozen=True)
class Excited(StepResult):
    """The multisine's record: ``seconds`` at ``level_V_rms`` (V_Td)."""

    seconds: float
    level_V_rms: float


@dataclass(frozen=True)
class TorqueOff(StepResult):
    """The command torque set back to ``V_Td`` (0)."""

    V_Td: float


URAD = 1e-6
#: the recorded channels' ADC ranges (V): the amplifier input is millivolts, tens of them in the
#: gyro modes, where the network amplifies the pickoff noise (Mode 5 Y: 7 mV rms, 35 mV peaks;
#: the pickoff itself 0.1 V rms, 0.47 V peaks)
RANGES_V = {"cmd": 10.0, "ac_ctl": 1.0, "ac_inst": 1.0, "gyro": 1.0, "pa": 0.05}
GYRO_MODE_RANGES_V = {"gyro": 2.0, "pa": 0.2}


@dataclass
class ExcitationParams:
    axis: Annotated[str, OneOf("X", "Y", note="Z has no primary autocollimator channel")] = "X"
    #: 3 autocollimator stabilization; 4 and 5 gyro stabilization (entered from caged Mode 3)
    mode: Annotated[
        int, OneOf(3, 4, 5, note="the stabilized modes; the gyro modes need the gyros caged")
    ] = 3
    rate_hz: Annotated[float, sample_rate()] = 1000.0
    #: V_Td updates per second (a DAC set-point between ADC blocks); rate_hz / update_hz whole
    update_hz: Annotated[float, Range(1.0, MAX_PROCEDURE_RATE_HZ, units="Hz")] = 250.0
    settle_s: Annotated[float, at_least(0)] = 20.0
    #: after the switch to Mode 4 or 5: the network's input steps from the control channel to
    #: the pickoff, and its slowest pole (w1, 0.15 rad/s: 6.7 s) and the caging loop through the
    #: autocollimator (0.1 rad/s, zeta 0.7: 14 s) ring on; their free response in the quiet
    #: record is output the network's input does not explain (H1 read 0.3 dB, 2 deg off at
    #: 0.5 Hz after 10 s)
    mode_settle_s: Annotated[float, at_least(0)] = 90.0
    quiet_s: Annotated[float, above(0)] = 120.0
    probe_s: Annotated[float, above(0)] = 16.0
    excite_s: Annotated[float, above(0)] = 256.0
    #: the excitation's flat band (the thesis's was white to 30 Hz)
    band_lo_hz: Annotated[float, above(0)] = 0.1
    band_hi_hz: Annotated[float, above(0)] = 60.0
    #: the platform motion to aim for, rms (the thesis's run: about 13 urad). Small, for Dahl
    #: bearings (eq. 5.2) are a spring only well inside To / (eta To^2), 39 urad on X: on the
    #: thesis rig k read 396 N m/rad at 2 urad, 366 at 4 and 296 at 10 (eta To^2 = 410)
    target_urad: Annotated[float, above(0)] = 2.0
    #: ... and at least this many times the quiet record's rms: in the gyro modes the platform
    #: follows the pickoff noise (Mode 5 Y: 4.9 urad rms), and an excitation below it is lost
    above_quiet: Annotated[float, at_least(0)] = 1.5
    #: V_Td rms of the probe
    probe_V: Annotated[float, above(0)] = 0.05
    max_range_fraction: Annotated[float, above(0)] = 0.6
    #: Welch segment of the quiet record (bin spacing 1/seg_s), the excitation's period (its
    #: line spacing 1/period_s: the platform's resonance is about 0.2 Hz wide), jackknife blocks
    seg_s: Annotated[float, above(0)] = 8.0
    period_s: Annotated[float, above(0)] = 16.0
    n_blocks: Annotated[int, at_least(3)] = 8
    #: the band the network and the platform are fitted over
    fit_lo_hz: Annotated[float, above(0)] = 0.5
    network_hi_hz: Annotated[float, above(0)] = 100.0
    platform_hi_hz: Annotated[float, above(0)] = 50.0
    #: the band the closed-loop roots are fitted over (Tables 5 and 6: 5-160 rad/s)
    roots_lo_hz: Annotated[float, above(0)] = 0.3
    roots_hi_hz: Annotated[float, above(0)] = 50.0
    seed: Annotated[int, at_least(0)] = 1

    def __post_init__(self) -> None:
        self.axis = str(self.axis).upper()
        check_limits(self, "excitation")
        per = self.rate_hz / self.update_hz
        if abs(per - round(per)) > 1e-9 or round(per) < 1:
            raise ValueError(
                f"excitation: rate_hz / update_hz = {per:g} samples per V_Td update must be a whole "
                f"number >= 1"
            )
        if not self.band_lo_hz < self.band_hi_hz <= self.update_hz / 2:
            raise ValueError(
                f"excitation: band_lo_hz..band_hi_hz = {self.band_lo_hz:g}..{self.band_hi_hz:g} Hz must "
                f"lie below half the update rate (update_hz / 2 = {self.update_hz / 2:g} Hz), low below high"
            )
        if self.quiet_s < self.seg_s * self.n_blocks:
            raise ValueError(
                f"excitation: quiet_s = {self.quiet_s:g} s holds fewer than n_blocks = {self.n_blocks} "
                f"segments of {self.seg_s:g} s"
            )
        if self.excite_s < self.period_s * (self.n_blocks + 1):
            raise ValueError(
                f"excitation: excite_s = {self.excite_s:g} s holds fewer than n_blocks + 1 = "
                f"{self.n_blocks + 1} periods of {self.period_s:g} s (the first is the transient)"
            )
        for name, per in (
            ("period_s", self.period_s * self.update_hz),
            ("period_s", self.period_s * self.rate_hz),
        ):
            if abs(per - round(per)) > 1e-6:
                raise ValueError(
                    f"excitation: {name} = {self.period_s:g} s must be whole V_Td updates and samples"
                )
        if not (
            self.fit_lo_hz < min(self.network_hi_hz, self.platform_hi_hz) <= self.rate_hz * 0.3
            and self.roots_lo_hz < self.roots_hi_hz <= self.rate_hz * 0.3
        ):
            raise ValueError(
                f"excitation: the fit bands fit_lo_hz..network_hi_hz / platform_hi_hz = "
                f"{self.fit_lo_hz:g}..{self.network_hi_hz:g} / {self.platform_hi_hz:g} Hz and "
                f"roots_lo_hz..roots_hi_hz = {self.roots_lo_hz:g}..{self.roots_hi_hz:g} Hz must lie below "
                f"the anti-alias filter (0.3 rate_hz = {self.rate_hz * 0.3:g} Hz), low below high"
            )


Params = ExcitationParams


#: a probe that moves the platform less than PROBE_ENOUGH x the target is repeated PROBE_GROWTH
#: times as strong, at most PROBE_TRIES probes in all
PROBE_ENOUGH, PROBE_GROWTH, PROBE_TRIES = 0.2, 4.0, 4
#: a platform fit that misses its bins by more than this many standard errors rms is an axis not
#: linear at the test amplitude (a linear one leaves 1.1-1.5, Dahl bearings 2.7-5.5)
NONLINEAR_RESIDUAL = 3.0
#: peak / rms of a channel's excited part (a random-phase multisine is near Gaussian: 4.5 sigma is
#: reached about once in the 2.5e5 samples of an excitation)
CREST = 4.5


def coherent_rms(
    x: np.ndarray, y: np.ndarray, fs: float, band_hz: tuple[float, float], seg_s: float = 2.0
) -> float:
    """The rms of ``y``'s part coherent with ``x`` in ``band_hz``: the integral of
    gamma^2 S_yy, gamma^2 freed of its bias over the averaged segments (Ch. V C)."""
    nperseg = min(int(round(seg_s * fs)), len(x))
    f, S = welch_csd_matrix(np.vstack([x, y]), fs, nperseg=nperseg)
    m = (
        equivalent_dof("hann", nperseg, nperseg // 2, n_segments(len(x), nperseg, nperseg // 2))
        / 2.0
    )
    g = unbiased_coherence(coherence(S)[:, 0, 1], m)
    band = (f >= band_hz[0]) & (f <= band_hz[1])
    return float(np.sqrt(np.sum((g * S[:, 1, 1].real)[band]) * (f[1] - f[0])))


def excitation_signal(
    n: int, update_hz: float, lo_hz: float, hi_hz: float, seed: int
) -> np.ndarray:
    """``n`` values of unit-rms noise, flat from ``lo_hz`` to ``hi_hz`` (random phases, equal
    amplitudes: a periodic multisine of period n / update_hz), one per V_Td update."""
    rng = np.random.default_rng(seed)
    f = np.fft.rfftfreq(n, 1.0 / update_hz)
    spec = np.zeros(f.size, complex)
    band = (f >= lo_hz) & (f <= hi_hz)
    if not band.any():
        raise ValueError(
            f"no frequency of a {n / update_hz:g} s excitation lies in {lo_hz:g}-{hi_hz:g} Hz"
        )
    spec[band] = np.exp(2j * np.pi * rng.random(int(band.sum())))
    x = np.fft.irfft(spec, n)
    return x / np.sqrt(np.mean(x * x))


class Excitation(Procedure[ExcitationParams]):
    name = "excitation"
    demo_order = 60
    #: Mode 3, then Mode 4 with records shorter than a lab's (the roots need no more)
    demo_runs = (("X", ()), ("X", ("mode=4", "quiet_s=64", "excite_s=160", "mode_settle_s=40")))
    title = (
        "Coherent excitation through V_Td in Mode 3, 4 or 5: network, inertia, stiffness, closed-loop roots "
        "(Ch. V C-D, Tables 5-6)"
    )
    json_keys = (
        "network",
        "inertia_kg_m2",
        "damping_Nms",
        "stiffness_Nm_per_rad",
        "excitation_amplitude_urad",
        "amplitude_dependent",
        "closed_loop",
        "file",
    )
    Params = ExcitationParams
    mode = 3

    def __init__(self, params: ExcitationParams | None = None, **kw: Any) -> None:
        super().__init__(params, **kw)
        p = self.params
        self.axis = p.axis
        self.mode = p.mode
        self.rate_hz = p.rate_hz
        #: one ADC read per V_Td update (not ``block_s``, the recording's read size: the quiet
        #: record and Mode 3's polls read in the default blocks, not a few samples at a time)
        self.update_s = 1.0 / p.update_hz
        a = p.axis.lower()
        self.names = {
            "cmd": f"cmd_{a}",
            "ac_ctl": f"ac_{a}_ctl",
            "ac_inst": f"ac_{a}_inst",
            "gyro": f"gyro_{a}",
            "pa": f"pa_{a}",
        }
        # the network's input: the control channel in Mode 3, the axis gyro's pickoff in 4 and 5 (Fig. 27)
        self.network_input = self.names["ac_ctl"] if p.mode == 3 else self.names["gyro"]
        ranges = RANGES_V | (GYRO_MODE_RANGES_V if p.mode != 3 else {})
        self.channel_ranges_V: dict[str, float] = {self.names[k]: v for k, v in ranges.items()}
        self.ranges_V = self.channel_ranges_V

    def channels(self) -> tuple[str, ...]:
        return tuple(self.names.values())

    def headline(self) -> dict[str, tuple[str, ...]]:
        """The headline figures and their channels (``Procedure.headline``): the platform's;
        ``network`` and ``closed_loop`` are fits of their own shape."""
        figures = ("inertia_kg_m2", "damping_Nms", "stiffness_Nm_per_rad")
        return dict.fromkeys(figures, (self.params.axis,))

    def plan(self) -> list[Step[Any]]:
        p = self.params
        steps: list[Step[Any]] = [
            Step("mode 3", bring_to_mode3, expected_s=300.0, setup=True, result=InMode3),
            Step("settle", self._settle, expected_s=p.settle_s, setup=True, result=Waited),
        ]
        if p.mode != 3:
            steps.append(
                Step(
                    f"mode {p.mode}",
                    partial(enter_gyro_mode, mode=p.mode, settle_s=p.mode_settle_s),
                    expected_s=p.mode_settle_s,
                    setup=True,
                    result=ModeSet,
                )
            )
        steps += [
            Step("quiet", self._quiet, expected_s=p.quiet_s, result=Recorded),
            Step("probe", self._probe, expected_s=p.probe_s, setup=True, result=Probe),
            Step("excite", self._excite, expected_s=p.excite_s, result=Excited),
            Step("V_Td off", self._off, expected_s=2.0, setup=True, result=TorqueOff),
        ]
        if p.mode != 3:
            steps.append(
                Step("back to mode 3", back_to_mode3, expected_s=2.0, setup=True, result=ModeSet)
            )
        return steps

    def _settle(self, ctx: Context) -> Waited:
        ctx.rig.set_command_torque_V(self.params.axis, 0.0)
        ctx.acquire(self.params.settle_s, keep=False)
        return Waited(seconds=self.params.settle_s)

    def _quiet(self, ctx: Context) -> Recorded:
        ctx.acquire(self.params.quiet_s, keep=False)
        return Recorded(seconds=self.params.quiet_s)

    def _period(self) -> np.ndarray:
        """One period of the unit-rms multisine, a value per V_Td update."""
        p = self.params
        return excitation_signal(
            int(round(p.period_s * p.update_hz)), p.update_hz, p.band_lo_hz, p.band_hi_hz, p.seed
        )

    def _inject(
        self, ctx: Context, volts_rms: float, seconds: float, keep: bool
    ) -> np.ndarray | None:
        """``seconds`` of the excitation at ``volts_rms``: a V_Td set-point every ``update_s``."""
        p = self.params
        n = int(round(seconds * p.update_hz))
        x = np.resize(self._period(), n) * volts_rms  # whole periods, repeated
        blocks = []

        def acquire(seconds: float) -> None:
            got = ctx.acquire(seconds, keep=keep)  # type: ignore[call-overload]
            if keep:
                blocks.append(got)

        # ends at 0 V, however it ends
        ctx.rig.stream_command_torque_V(p.axis, x, self.update_s, acquire)
        return np.concatenate(blocks) if keep else None

    def _probe(self, ctx: Context) -> Probe:
        """The level (V_Td rms) that moves the platform ``target_urad`` rms, cut to the ranges.

        The motion is the control channel's part coherent with the probe: in the gyro modes the
        platform already follows the pickoff noise by several urad rms, which a comparison of
        rms levels cannot see past. A probe that moves nothing measurable is repeated at
        ``PROBE_GROWTH`` times the level, up to the DAC's limit."""
        p = self.params
        cal = ctx.rig.calibration
        quiet = ctx.acquire(min(p.probe_s, 8.0))
        cols = {k: self.channels().index(n) for k, n in self.names.items()}
        for k, name in self.names.items():
            col = quiet[:, cols[k]]
            if k != "cmd" and np.nanmax(np.abs(col)) >= 0.99 * self.channel_ranges_V[name]:
                raise ProcedureError(
                    f"excitation: {name} is at its full scale ({self.channel_ranges_V[name]:g} V) "
                    f"with nothing injected: the platform is not at rest in Mode {p.mode} (an "
                    f"unstable loop, or a gimbal on its stop); nothing was injected"
                )
        crest = float(np.max(np.abs(self._period())))
        dac_max = 0.9 * min(cal.dac_range_V, self.channel_ranges_V[self.names["cmd"]]) / crest
        skip = int(round(min(2.0, p.probe_s / 4) * p.rate_hz))  # the loop's transient
        scale = cal.autocollimator[p.axis].control_mV_per_urad * 1e-3 / URAD
        rms_q = float(np.nanstd(quiet[:, cols["ac_ctl"]])) / scale / URAD
        target = max(p.target_urad, p.above_quiet * rms_q)
        level, tries = min(p.probe_V, dac_max), []
        while True:
            data = self._inject(ctx, level, p.probe_s, keep=True)
            assert data is not None
            moved = (
                coherent_rms(
                    data[skip:, cols["cmd"]],
                    data[skip:, cols["ac_ctl"]],
                    p.rate_hz,
                    (p.band_lo_hz, p.band_hi_hz),
                )
                / scale
                / URAD
            )
            tries.append(ProbeTry(V_rms=round(level, 6), moved_urad_rms=round(moved, 4)))
            if moved >= PROBE_ENOUGH * target or level >= dac_max or len(tries) >= PROBE_TRIES:
                break
            level = min(level * PROBE_GROWTH, dac_max)
        if not moved > 0:
            raise ProcedureError(
                f"excitation: probes up to {level:g} V rms did not move the platform measurably "
                f"(no part of ac_{p.axis.lower()}_ctl coherent with V_Td; quiet {rms_q:.3g} urad "
                f"rms): is the command-torque DAC connected?"
            )
        limits = {"target": level * target / moved}
        # each channel's peak: its quiet peak plus the excited part's, which scales with the level
        # (a channel's noise does not: in the gyro modes the pickoff noise fills half the range)
        for k, name in self.names.items():
            if k == "cmd":
                continue
            room = p.max_range_fraction * self.channel_ranges_V[name] - float(
                np.nanmax(np.abs(quiet[:, cols[k]] - np.nanmean(quiet[:, cols[k]])))
            )
            if room <= 0:
                raise ProcedureError(
                    f"excitation: {name}'s quiet peaks already exceed {p.max_range_fraction:g} of its "
                    f"{self.channel_ranges_V[name]:g} V range: no room to excite (raise "
                    f"max_range_fraction, or quieten the rig)"
                )
            var = float(np.nanvar(data[skip:, cols[k]]) - np.nanvar(quiet[:, cols[k]]))
            if var > 0:
                limits[name] = level * room / (CREST * var**0.5)
        limits["V_Td DAC"] = dac_max
        by = min(limits, key=lambda k: limits[k])
        chosen = limits[by]
        return Probe(
            probe_V_rms=round(level, 6),
            probe_motion_urad_rms=round(moved, 4),
            quiet_urad_rms=round(rms_q, 4),
            probes=tuple(tries),
            target_urad_rms=round(target, 4),
            level_V_rms=chosen,
            limited_by=by,
            expected_motion_urad_rms=round(moved * chosen / level, 4),
        )

    def _excite(self, ctx: Context) -> Excited:
        level = ctx.result("probe", Probe).level_V_rms
        self._inject(ctx, level, self.params.excite_s, keep=False)
        return Excited(seconds=self.params.excite_s, level_V_rms=level)

    def _off(self, ctx: Context) -> TorqueOff:
        ctx.rig.set_command_torque_V(self.params.axis, 0.0)
        ctx.acquire(1.0, keep=False)
        return TorqueOff(V_Td=0.0)

    # ------------------------------------------------------------------ analysis
    def _kg(
        self, p: ExcitationParams, cal: RigCalibration
    ) -> tuple[dict[str, float], dict[str, str]]:
        """The axis gyro's K_g (mV/urad): the stopwatch's where the campaign has it."""
        return prior_values(
            self.prior, "stopwatch", "K_g_mV_per_urad", [p.axis], cal.pickoff_scale_mV_per_urad
        )

    def _pickoff(self, p: ExcitationParams, cal: RigCalibration) -> tuple[float, float] | None:
        """The stopwatch's K_g and its relative 95 % half-width, for the gyro modes' loop."""
        kg, src = self._kg(p, cal)
        if p.mode == 3 or src[p.axis] != "stopwatch":
            return None
        return kg[p.axis], pickoff_scale_rel_half_width(self.prior, "stopwatch", p.axis, kg[p.axis])

    def analyze(self, ctx: Context) -> Analysis:
        p = self.params
        cal = ctx.rig.calibration
        n = self.names
        try:
            quiet = block_csd(
                [(s.file, s.start, s.stop) for s in ctx.data_spans(["quiet"])],
                [self.network_input, n["pa"]],
                p.seg_s,
                p.n_blocks,
            )
            excited = periodic_blocks(
                [(s.file, s.start, s.stop) for s in ctx.data_spans(["excite"])],
                [n["cmd"], n["pa"], n["ac_ctl"], n["ac_inst"], n["gyro"]],
                p.period_s,
                p.n_blocks,
            )
            net_resp = response(quiet, self.network_input, n["pa"])
            quiet_net = fit_network(
                net_resp, max(p.fit_lo_hz, quiet.lowest_fit_hz), p.network_hi_hz
            )
            plat_resp = response(excited, n["pa"], n["ac_inst"], via=n["cmd"])
            plat = fit_platform(
                plat_resp,
                cal.platform[p.axis],
                cal.autocollimator[p.axis],
                max(p.fit_lo_hz, excited.lowest_fit_hz),
                p.platform_hi_hz,
            )
            roots, loop_resp, net = closed_loop(
                excited, quiet_net, plat, cal, n, self.network_input, p, self._pickoff(p, cal)
            )
        except TransferError as exc:
            raise ProcedureError(f"excitation: {exc}") from None
        values = analysis_values(net, plat, p.axis, cal.platform[p.axis].inertia_kg_m2)
        amplitude = excited_amplitude_urad(
            excited,
            n["cmd"],
            n["ac_inst"],
            cal.autocollimator[p.axis],
            (p.band_lo_hz, p.band_hi_hz),
        )
        values |= amplitude_labels(plat, p.axis, amplitude)
        probe = ctx.result("probe", Probe)
        values["level_V_rms"] = probe.level_V_rms
        values["level_limited_by"] = probe.limited_by
        values["mode"] = p.mode
        values["closed_loop"] = roots.values() | {"thesis": thesis_roots(p.mode, p.axis)}
        kg, kg_src = self._kg(p, cal)
        ac = cal.autocollimator[p.axis]
        scales = {
            n["ac_ctl"]: ac.control_mV_per_urad * 1e-3,
            n["ac_inst"]: ac.inst_mV_per_urad * 1e-3,
            n["gyro"]: kg[p.axis] * 1e-3,
        }
        values["incoherent"] = incoherent_parts(excited, n, p, scales)
        if p.mode == 3:
            # the gyro's incoherent part is its pickoff noise (and the platform's unexcited motion,
            # ~0.4 urad rms on the thesis rig against ~2.7 urad of pickoff noise in 1-50 Hz). Not
            # in the gyro modes: there the loop closes on the pickoff and reshapes its noise
            values["pickoff_noise_urad_rms"] = {
                p.axis: round(
                    values["incoherent"][n["gyro"]]["incoherent_rms_V"] / (kg[p.axis] * 1e-3), 5
                )
            }
            values["pickoff_noise_band_hz"] = [1.0, 50.0]
            values["pickoff_scale_source"] = kg_src
        ms = measurements(net, plat, values, p) + root_measurements(roots, p)
        figures = [
            Figure(
                "network",
                "Compensation network, control channel to amplifier input: the quiet record's "
                "H1 with 95 % intervals (cf. Fig. 40), the fit inside the excited loop and the design",
                partial(
                    plot_response,
                    resp=net_resp,
                    fit=net,
                    design=lambda f: network_response(f, DESIGN_NETWORK),
                ),
            ),
            Figure(
                "platform",
                "Platform, amplifier input to instrumentation angle through V_Td: measured "
                "with 95 % intervals and the fit (cf. Fig. 52)",
                partial(plot_response, resp=plat_resp, fit=plat, design=None),
            ),
            Figure(
                "loop",
                f"Loop sensitivity in Mode {p.mode}, V_Td to amplifier input: measured with 95 % "
                f"intervals (the closed-loop roots' check, Tables 5-6)",
                partial(plot_response, resp=loop_resp, fit=None, design=None),
            ),
        ]
        title = f"{Path(ctx.path).name}, axis {p.axis}, Mode {p.mode}"
        return Analysis(values, ms, figures, markdown(values, title))


def closed_loop(
    excited: BlockCsd,
    net: ModelFit,
    plat: ModelFit,
    cal: RigCalibration,
    n: Mapping[str, str],
    network_input: str,
    p: ExcitationParams,
    pickoff: tuple[float, float] | None = None,
) -> tuple[ClosedLoop, Response, ModelFit]:
    """The loop closed over the identified network, platform and sensor (``analysis.roots``),
    the measured sensitivity pa / V_Td it is checked against, and the network fitted inside the
    excited loop (``net``, the quiet record's fit, is only its start). ``pickoff``: the
    stopwatch's K_g (mV/urad) and its relative 95 % half-width; in the gyro modes the loop
    alone's sensor, where the gain measured inside the loop carries the cross-axis coupling
    (``roots.IN_LOOP_GAIN_ALLOWANCE``)."""
    kind = "ctl" if p.mode == 3 else "gyro"
    pc, ac = cal.platform[p.axis], cal.autocollimator[p.axis]
    lo = max(p.roots_lo_hz, excited.lowest_fit_hz)
    ratio = response(excited, n["ac_inst"], network_input, via=n["cmd"])
    caging = (
        None
        if p.mode == 3
        else GyroCaging(
            cal.caging_natural_rad_per_s[p.axis],
            cal.caging_zeta[p.axis],
            cal.restraint_time_constant_s[p.axis],
        )
    )
    k_loop, k_loop_reps = sensor_gain(ratio, kind, ac, lo, p.platform_hi_hz, caging)
    dof = len(k_loop_reps) - 1
    gain, gain_reps, rel, source, check = k_loop, k_loop_reps, 0.0, "measured in the loop", None
    if kind == "gyro":
        # the in-loop gain is the loop alone's only to the coupling's allowance
        rel = IN_LOOP_GAIN_ALLOWANCE
        if pickoff is not None:
            check = sensor_estimate(k_loop, k_loop_reps, dof, rel)
            gain, rel, source = pickoff[0] * 1e3, pickoff[1], "stopwatch"
            gain_reps = [gain] * len(k_loop_reps)

    # the network again, inside the excited loop: the quiet record's H1 is biased at the lowest
    # frequencies by the network's memory (``network_in_loop``), and c1 lives there
    in_loop = fit_network(
        network_in_loop(excited, network_input, n["pa"], n["cmd"], pc.command_divider),
        lo,
        p.roots_hi_hz,
        start=net.params,
    )

    def parts(netp: Mapping[str, float], platp: Mapping[str, float], g: float) -> LoopParts:
        return LoopParts(
            netp,
            platp["inertia_kg_m2"],
            platp["damping_Nms"],
            platp["stiffness_Nm_per_rad"],
            g,
            caging,
        )

    reps = [parts(a, b, g) for a, b, g in zip(in_loop.replicates, plat.replicates, gain_reps)]
    sens = response(excited, n["cmd"], n["pa"])
    return (
        close_loop(
            p.mode,
            parts(in_loop.params, plat.params, gain),
            reps,
            pc,
            ac,
            sens,
            (lo, p.roots_hi_hz),
            len(reps) - 1,
            gain_reps,
            sensor_rel_half=rel,
            sensor_from=source,
            sensor_in_loop=check,
        ),
        sens,
        in_loop,
    )


def excited_amplitude_urad(
    excited: BlockCsd,
    cmd: str,
    angle: str,
    ac: AutocollimatorConstants,
    band_hz: tuple[float, float],
) -> float:
    """The platform's excited motion, urad rms: the part of the instrumentation channel
    coherent with V_Td (gamma^2 S, Ch. V C; gamma^2 freed of its bias over the periods) over the
    excitation's band, with the channel's scale and filter (eq. 3.22) divided out. It is the
    amplitude at which a nonlinear bearing's describing function (eq. 5.12) is measured."""
    S = excited.mean()
    r, i = excited.index(cmd), excited.index(angle)
    f = excited.f
    band = (f >= band_hz[0]) & (f <= band_hz[1])
    g = unbiased_coherence(coherence(S)[:, r, i], excited.averages())
    filt = np.abs(sensor_filter(f[band], ac, angle)) ** 2
    power = np.sum((g * S[:, i, i].real)[band] / filt) * (f[1] - f[0])
    return float(np.sqrt(power)) / sensor_scale_V_per_rad(ac, angle) / URAD


def amplitude_labels(plat: ModelFit, axis: str, amplitude_urad: float) -> dict[str, Any]:
    """The amplitude the platform's figures hold at, and which of them depend on it.

    A linear axis (eqs. 3.23-3.27) has one k and one D at every amplitude. A Dahl bearing
    (eq. 5.2) has none: what the fit gives is its describing function (eq. 5.12) at this motion,
    the stiffness falling and the dissipation growing with the amplitude. The data say which:
    a damping that depends on frequency (``transfer.local_damping``), or a fit that misses its
    bins by more than 3 standard errors, is an axis that is not linear at this amplitude; then
    ``amplitude_dependent`` is true for k and D (the inertia is a mass: never)."""
    nonlinear = (
        bool(plat.local_damping is not None and plat.local_damping.frequency_dependent())
        or plat.residual_normalized > NONLINEAR_RESIDUAL
    )
    out: dict[str, Any] = {
        "excitation_amplitude_urad": {axis: round(amplitude_urad, 4)},
        "amplitude_dependent": {
            "inertia_kg_m2": {axis: False},
            "damping_Nms": {axis: nonlinear},
            "stiffness_Nm_per_rad": {axis: nonlinear},
        },
    }
    if plat.local_damping is not None:
        out["platform_fit_local_damping"] = plat.local_damping.values()
    return out


def root_measurements(roots: ClosedLoop, p: ExcitationParams) -> list[Measurement]:
    ms = []
    for name, r in roots.named.items():
        z = (
            ""
            if r.zeta is None
            else (
                f", zeta {r.zeta.value:.3g} [{r.zeta.lo:.3g}, {r.zeta.hi:.3g}]"
                if r.zeta.resolved
                else f", zeta not resolved: {r.zeta.why}"
            )
        )
        ms.append(
            Measurement(
                f"closed-loop root {name} ({p.axis}, Mode {p.mode})",
                r.w.value if r.w.resolved else None,
                "rad/s",
                note=(
                    f"95 % [{r.w.lo:.4g}, {r.w.hi:.4g}]"
                    if r.w.resolved
                    else f"not resolved: {r.w.why}"
                )
                + z,
            )
        )
    ms.append(
        Measurement(
            "closed model against the measured sensitivity / standard error",
            roots.check_normalized,
            "rms",
            note=f"{roots.check_db_rms:.3g} dB, {roots.check_deg_rms:.3g} deg rms unweighted"
            + "".join(f"; {x}" for x in roots.notes),
        )
    )
    return ms


def analysis_values(
    net: ModelFit, plat: ModelFit, axis: str, datasheet_inertia: float
) -> dict[str, Any]:
    values: dict[str, Any] = {
        "axis": axis,
        "network": net.values(),
        "network_design": {k: DESIGN_NETWORK[k] for k in ("gain", *NETWORK_CORNERS)},
    }
    f = np.geomspace(0.3, 50.0, 200)
    assert net.curve is not None
    d = net.curve(f) / network_response(f, DESIGN_NETWORK)
    values["network_vs_design_max_db"] = float(np.max(np.abs(20 * np.log10(np.abs(d)))))
    values["network_vs_design_max_deg"] = float(np.max(np.abs(np.degrees(np.angle(d)))))
    for key in ("inertia_kg_m2", "damping_Nms", "stiffness_Nm_per_rad"):
        add_figure(values, key, {axis: plat.estimates[key]})
    why = {k: e.why for k, e in plat.estimates.items() if not e.resolved}
    if why:
        values["platform_why_unresolved"] = why
    values["platform_fit"] = {
        k: v
        for k, v in plat.values().items()
        if k
        in (
            "band_hz",
            "bins",
            "residual_db_rms",
            "residual_deg_rms",
            "residual_normalized",
            "notes",
        )
    }
    values["datasheet_inertia_kg_m2"] = datasheet_inertia
    return values


def incoherent_parts(
    excited: Any,
    n: Mapping[str, str],
    p: ExcitationParams,
    scales_V_per_urad: Mapping[str, float] | None = None,
) -> dict[str, Any]:
    """Each sensor's spectrum split by its coherence with V_Td (Ch. V C): the rms (V) of the
    coherent part gamma^2 S and of the incoherent part (1 - gamma^2) S over 1-50 Hz. gamma^2 is
    first freed of its bias over m averaged periods, (m gamma^2 - 1) / (m - 1) (for no coherence
    E[gamma^2] = 1 / m, which read the incoherent part 7 % low with 15 periods).

    With the sensors' scales, the incoherent part also in urad: its rms (the sensor's noise
    equivalent angle in the band, with the platform's unexcited motion) and its median level
    (the noise floor, urad/sqrt(Hz)). For the sensor the loop closes on (the control channel in
    Mode 3, the pickoff in 4 and 5) the loop reshapes its own noise: ``in_loop`` says so, and
    the open-loop figure is the ``baseline`` procedure's."""
    S = excited.mean()
    m = excited.averages()
    coh = coherence(S)
    f = excited.f
    band = (f >= 1.0) & (f <= 50.0)
    df = f[1] - f[0]
    r = excited.index(n["cmd"])
    loop_sensor = "ac_ctl" if p.mode == 3 else "gyro"
    out: dict[str, Any] = {}
    for k in ("ac_ctl", "ac_inst", "gyro"):
        i = excited.index(n[k])
        s = S[:, i, i].real
        g = unbiased_coherence(coh[:, r, i], m)
        incoherent = float(np.sqrt(np.sum(((1 - g) * s)[band]) * df))
        part: dict[str, Any] = {
            "coherent_rms_V": float(np.sqrt(np.sum((g * s)[band]) * df)),
            "incoherent_rms_V": incoherent,
            "band_hz": [1.0, 50.0],
            "in_loop": k == loop_sensor or (p.mode == 3 and k == "ac_inst"),
        }
        if scales_V_per_urad and n[k] in scales_V_per_urad:
            sc = scales_V_per_urad[n[k]]
            part["incoherent_urad_rms"] = round(incoherent / sc, 5)
            part["floor_urad_per_rtHz"] = round(
                float(np.sqrt(np.median(((1 - g) * s)[band]))) / sc, 6
            )
        out[n[k]] = part
    return out


def measurements(
    net: ModelFit, plat: ModelFit, values: Mapping[str, Any], p: ExcitationParams
) -> list[Measurement]:
    ms = []
    amp = values["excitation_amplitude_urad"][p.axis]
    for key, unit in (
        ("inertia_kg_m2", "kg m^2"),
        ("damping_Nms", "N m s"),
        ("stiffness_Nm_per_rad", "N m/rad"),
    ):
        e = plat.estimates[key]
        label = (
            f" (describing function at {amp:.3g} urad rms)"
            if values["amplitude_dependent"][key][p.axis]
            else ""
        )
        ms.append(
            Measurement(
                f"{key} ({p.axis}){label}",
                e.value if e.resolved else None,
                unit,
                note=(
                    f"95 % [{e.lo:.4g}, {e.hi:.4g}]"
                    if e.resolved
                    else f"not resolved, 95 % [{e.lo:.4g}, {e.hi:.4g}]: {e.why}"
                ),
            )
        )
    ms.append(
        Measurement(
            f"platform motion excited ({p.axis}), coherent with V_Td",
            amp,
            "urad rms",
            note=f"{p.band_lo_hz:g}-{p.band_hi_hz:g} Hz, the amplitude k and D are measured at",
        )
    )
    # residuals in units of each bin's own standard error: about 1 when the model fits. The
    # platform's is no limit: a Dahl bearing is not linear, and the intervals are widened by it
    ms.append(
        Measurement(
            "platform fit residual / standard error",
            plat.residual_normalized,
            "rms",
            note=f"{plat.residual_db_rms:.3g} dB, {plat.residual_deg_rms:.3g} deg rms unweighted"
            + (
                "; above 3: the axis is not linear at this amplitude (Dahl friction?), so k and D are "
                "its describing function there, intervals widened by the ratio"
                if plat.residual_normalized > 3
                else ""
            ),
        )
    )
    ms.append(
        Measurement(
            "network fit residual / standard error",
            net.residual_normalized,
            "rms",
            hi=3.0,
            note=f"{net.residual_db_rms:.3g} dB, {net.residual_deg_rms:.3g} deg rms unweighted",
        )
    )
    ms.append(
        Measurement(
            "network against the design, worst over 0.3-50 Hz",
            values["network_vs_design_max_db"],
            "dB",
            note=f"{values['network_vs_design_max_deg']:.3g} deg (a comparison, not a limit)",
        )
    )
    return ms


PROCEDURE = Excitation
