"""The model-gap workflow: find where the measurement and the model disagree, name the missing
effect, close the gap, and look again (Ch. V E-F made a procedure; docs/gap.md).

1. Read any "fbs-run" file; the model is the nominal plant (Ch. III, no bearing torque) with
   the file's mode, channels and rate.
2. Compare band spectra with the model's expected spectra (``model.py``), its noise levels
   fitted, and look for steps in the time domain; locate the departures (``locate.py``).
3. Fit every catalogue effect by maximum likelihood and rank by BIC (``fit.py``); name the best.
4. Add it, compare again; repeat while a significant departure remains and a candidate
   explains it.
5. Report the gap (``locate.gap_db``) against the nominal and the refined model; with a
   report, simulate both with the measured run's channels, rate and duration.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from daq import provenance
from daq.reader import LOST_SAMPLES_NOTE, RunFile, lost_samples
from daq.runfile import RunWriter, make_folder
from drivers.rig_datasheet import AXES
from procedures.analysis.gap.fit import EffectFit, Fitter, NuisanceFit, bic_score, to_unit
from procedures.analysis.gap.grid import (
    GapInputError,
    Grid,
    band_spectra,
    bin_spectra,
    channel_weights,
    make_grid,
)
from procedures.analysis.gap.locate import Band, Evidence, bands, departures, gap_db
from procedures.analysis.gap.model import (
    SHAPE_KEYS,
    SpectralModel,
    apply_nuisance,
    lsb,
    quantization_psd,
    step_response,
)
from procedures.analysis.gap.pickoff_lines import MeasuredLine, found_pickoff_lines, refine_line
from procedures.analysis.gap.steps import (
    Step,
    find_steps,
    robust_scale,
    step_like,
    template_gain,
    window_difference,
)
from simhw import effects as catalogue
from simhw.config import Sampling, SimConfig, load_config, to_dict
from simhw.plant import AXIS_OF_CHANNEL, CHANNELS
from simhw.sampling import ADC_RANGES_V
from simhw.simulator import Simulator

log = logging.getLogger(__name__)

#: Command inputs echo the DACs: no plant response to compare.
SKIPPED_PREFIXES = ("cmd_",)
URAD = 1e-6


def channel_axis(name: str) -> str | None:
    """The platform axis a recorded channel responds to (ac_x_ctl -> X, gyro_xrd -> X)."""
    parts = name.split("_")
    if len(parts) < 2 or name.startswith(SKIPPED_PREFIXES):
        return None
    token = parts[1].upper()
    return AXIS_OF_CHANNEL.get(token, token if token in AXES else None)


@dataclass
class GapOptions:
    alpha: float = 0.01  # family-wise false-departure probability per file
    tol_db: float = 0.5  # model tolerance: smaller departures are not gaps
    min_score: float = (
        10.0  # BIC improvement for an effect to be named ("very strong", Kass-Raftery)
    )
    max_effects: int = 4  # three mains harmonics are three pickup lines
    refine_top: int = (
        3  # candidates refined after the screening (the rest keep their screened score)
    )
    # A named effect must close a material share of the gap where it acts, not only win on the
    # score (a small systematic improvement over thousands of bands always "wins"): at least
    # this share of the gap on its cells, and at least this many dB.
    min_closed_share: float = 0.4
    min_closed_db: float = 0.2
    #: after an effect is named, look for another even where no band departs (``analyse``)
    look_when_quiet: bool = True
    #: where no single candidate closes its share, pairs of the leading this many are fitted
    #: together (``_pair_that_closes``)
    pair_top: int = 3
    seed: int = 1  # of the model simulations
    sim_config: str | Path | None = None


@dataclass
class Record:
    path: Path
    axis: str
    mode: int
    rate_hz: float
    channels: tuple[str, ...]
    data: np.ndarray  # (n_channels, n) volts
    lsb_V: np.ndarray
    warnings: list[str] = field(default_factory=list)

    @property
    def duration_s(self) -> float:
        return self.data.shape[1] / self.rate_hz


def load_record(path: str | Path, axis: str | None = None) -> Record:
    """The file's channels of one axis, checked: every problem is a GapInputError naming it."""
    path = Path(path)
    if not path.exists():
        raise GapInputError(f"{path}: no such file")
    try:
        run = RunFile(path)
    except (OSError, ValueError) as e:
        raise GapInputError(f"{path}: not a readable fbs-run file ({e})") from None
    with run:
        attrs = run.attrs
        ax = axis or attrs.get("axis") or ""
        ax = ax.decode() if isinstance(ax, bytes) else str(ax)
        if not ax:
            raise GapInputError(
                f"{path}: the file has no 'axis' attribute; give the axis (--axis X, Y or Z)"
            )
        ax = ax.strip().upper()
        if ax not in AXES:
            raise GapInputError(f"{path}: unknown axis {ax!r}; the platform axes are X, Y and Z")
        try:
            mode = int(attrs["mode"])
        except (KeyError, TypeError, ValueError):
            raise GapInputError(
                f"{path}: root attribute 'mode' is {attrs.get('mode')!r}, not a mode 1..6"
            ) from None
        if mode not in range(1, 7):
            raise GapInputError(f"{path}: mode {mode} cannot be modelled (modes 1..6)")
        changes = [e for e in run.events if e.kind == "mode" and e.time_s > 0]
        if changes:
            raise GapInputError(
                f"{path}: the mode changes during the record (at {changes[0].time_s:.3f} s: "
                f"{changes[0].text}); the gap workflow needs one steady mode — cut the record"
            )
        present = list(run.lengths)
        wanted = [c for c in present if c in CHANNELS and channel_axis(c) == ax]
        if not wanted:
            need = [c for c in CHANNELS if channel_axis(c) == ax]
            raise GapInputError(
                f"{path}: missing channels: none of axis {ax}'s channels ({', '.join(need)}) is in "
                f"the file (it has {', '.join(present) or 'none'})"
            )
        rate = float(run.rate_hz)
        data = run.read(wanted)
        status = run.status
    warnings = []
    if status and status != "complete":
        warnings.append(f"file status is {status!r}: analysing the samples it holds")
    for c, x in zip(wanted, data):
        lost = lost_samples(c, x, rate)
        if lost:
            raise GapInputError(
                f"{path}: channel {lost} ({LOST_SAMPLES_NOTE}); the gap workflow needs every sample: "
                f"analyse a clean span (cut the record) or re-record"
            )
    steps = np.array([lsb(x) for x in data])
    keep = []
    for c, x, q in zip(wanted, data, steps):
        full = _range_from_lsb(q, Sampling().adc_bits)
        clipped = int(np.sum(np.abs(x) >= full - 1.5 * q)) if full else 0
        if clipped:
            warnings.append(
                f"{c} excluded: {clipped} samples at the ADC's full scale (+-{full:g} V): clipped "
                f"spectra are not the rig's; record it on a wider range"
            )
        elif q > 0 and np.std(x) < 3 * q:
            warnings.append(
                f"{c} excluded: its signal ({np.std(x):.3g} V rms) is within 3 LSB ({q:.3g} V) of "
                f"the ADC; record it on a finer range"
            )
        elif np.std(x) == 0:
            warnings.append(f"{c} excluded: constant")
        else:
            keep.append(c)
    if not keep:
        raise GapInputError(f"{path}: no usable channel of axis {ax}: " + "; ".join(warnings))
    idx = [wanted.index(c) for c in keep]
    return Record(path, ax, mode, rate, tuple(keep), data[idx], steps[idx], warnings)


@dataclass
class Finding:
    """One named effect, in the order found."""

    effect: str
    parameters: dict[str, float]
    uncertainties: dict[str, float]
    score: float
    runner_up: str
    margin: float  # score over the runner-up's
    gap_before_db: float  # on the bands located at this step, model expectation
    gap_after_db: float
    located: list[Band]
    candidates: list[dict[str, Any]]
    intervals: dict[str, tuple[float, float]] = field(
        default_factory=dict
    )  # 95 %, ``fit.Fitter._errors``
    at_bound: list[str] = field(default_factory=list)  # fitted parameters at a bound of their prior

    def parameter_text(self, sep: str = ", ") -> str:
        """``name = value [lo, hi]`` per parameter, with its 95 % interval where it has one."""

        def one(k: str, v: float) -> str:
            iv = self.intervals.get(k)
            return f"{k} = {v:.4g}" + (f" [{iv[0]:.4g}, {iv[1]:.4g}]" if iv else "")

        return sep.join(one(k, v) for k, v in self.parameters.items())


@dataclass
class GapResult:
    file: str
    axis: str
    mode: int
    rate_hz: float
    duration_s: float
    channels: tuple[str, ...]
    significant: bool
    findings: list[Finding]
    located: list[Band]
    steps: list[Step]
    step_channel: str | None
    gap_before_db: float
    gap_after_db: float
    candidates: list[dict[str, Any]]
    scales_before: dict[str, float]
    scales_after: dict[str, float]
    warnings: list[str]
    unexplained: bool  # a departure remains that no catalogue effect explains
    grid: Grid = field(repr=False)
    spectra: dict[str, np.ndarray] = field(repr=False, default_factory=dict)
    cfg_before: SimConfig | None = field(repr=False, default=None)
    cfg_after: SimConfig | None = field(repr=False, default=None)
    sim_gaps: tuple[float, float] | None = None  # the gaps against the simulated runs (--report)
    elapsed_s: float = 0.0
    #: what is left unexplained: the bands still departing from the refined model, the steps
    #: it does not make, and the best candidates that were not enough (and how little they close)
    remaining: list[Band] = field(default_factory=list)
    remaining_steps: list[Step] = field(default_factory=list)
    partial: list[dict[str, Any]] = field(default_factory=list)

    @property
    def effect(self) -> str:
        return self.findings[0].effect if self.findings else "none"

    def to_json(self) -> dict[str, Any]:
        """DESIGN.md section 7's keys (``effect``, ``parameters``, ``significant``, the gaps,
        ``candidates``), plus ``uncertainties`` and ``effects`` (every effect, in the order found)."""
        first = self.findings[0] if self.findings else None
        return {
            "effect": self.effect,
            "parameters": _rounded(first.parameters) if first else {},
            "uncertainties": _rounded(first.uncertainties) if first else {},
            "parameters_ci95": _rounded_intervals(first.intervals) if first else {},
            "significant": self.significant,
            "gap_before_db": round(self.gap_before_db, 3),
            "gap_after_db": round(self.gap_after_db, 3),
            "candidates": self.candidates,
            "effects": [
                {
                    "effect": f.effect,
                    "parameters": _rounded(f.parameters),
                    "parameters_ci95": _rounded_intervals(f.intervals),
                    "gap_closed_db": round(f.gap_before_db - f.gap_after_db, 3),
                }
                for f in self.findings
            ],
            "explained": not self.unexplained,
            "unexplained": (
                [
                    {
                        "channel": b.channel,
                        "f_lo_hz": round(b.f_lo_hz, 4),
                        "f_hi_hz": round(b.f_hi_hz, 4),
                        "deviation_db": round(b.deviation_db, 2),
                    }
                    for b in self.remaining
                ]
                + [
                    {"time_s": round(s.time_s, 3), "step_urad": round(s.size / URAD, 3)}
                    for s in self.remaining_steps
                ]
            ),
            "partial": self.partial,
            "file": self.file,
        }


def _rounded(d: dict[str, float]) -> dict[str, float | None]:
    return {k: (float(f"{v:.5g}") if math.isfinite(v) else None) for k, v in d.items()}


def _with_effects(
    cfg0: SimConfig, axis: str, fits: list[tuple[catalogue.Effect, EffectFit]]
) -> SimConfig:
    """The nominal configuration with these effects at their fitted values."""
    cfg = cfg0
    for eff, f in fits:
        cfg = eff.inject(
            cfg, axis, **{p.name: min(max(f.params[p.name], p.lo), p.hi) for p in eff.params}
        )
    return cfg


def _without(
    fitter: Fitter,
    cfg0: SimConfig,
    axis: str,
    in_model: list[tuple[catalogue.Effect, EffectFit]],
    i: int,
) -> NuisanceFit:
    """The model with every effect in it but the ``i``-th, its noise levels fitted (the nuisance
    parts the others own held)."""
    rest = [x for j, x in enumerate(in_model) if j != i]
    held, fitter.hold = fitter.hold, frozenset(p for e, _ in rest for p in e.owns)
    try:
        return fitter.base(_with_effects(cfg0, axis, rest))
    finally:
        fitter.hold = held


def _refit_jointly(
    fitter: Fitter,
    cfg0: SimConfig,
    axis: str,
    in_model: list[tuple[catalogue.Effect, EffectFit]],
    findings: list[Finding],
    evidence: Evidence,
    n_obs: int,
    opt: GapOptions,
) -> tuple[SimConfig, NuisanceFit]:
    """After an addition, each earlier effect re-fitted with all the others in the model, then
    the new one with the earlier ones as re-fitted (one pass, each from its values: two effects
    that overlap pull on each other, and the first fit of the new one was made beside the
    earlier ones' values from before it), then each kept only while it still earns its place: its removal,
    the others and the noise levels staying fitted, must cost at least ``opt.min_score`` of
    BIC. ``in_model`` and ``findings`` are updated in place (the same order); returns the
    refined model's configuration and noise fit."""
    for i, (eff, f) in enumerate(in_model):
        others = _with_effects(cfg0, axis, [x for j, x in enumerate(in_model) if j != i])
        again = fitter.fit(eff, others, evidence, start=f.params)
        if again is not None:
            again = fitter.held_envelope(eff, others, evidence, again)
            # a held parameter's spread came from the pass that found it (its line or steps are
            # no longer a departure now that the effect is in the model): it stays
            again.errors = f.errors | again.errors
            again.intervals = f.intervals | again.intervals
            log.info(
                "re-fitted %s with %s: %s",
                eff.name,
                ", ".join(e.name for j, (e, _) in enumerate(in_model) if j != i),
                again.params,
            )
            in_model[i] = (eff, again)
            fd = findings[i]
            fd.parameters, fd.uncertainties, fd.intervals = (
                again.params,
                again.errors,
                again.intervals,
            )
    cfg = _with_effects(cfg0, axis, in_model)
    cur = fitter.base(cfg)
    for i in reversed(range(len(in_model))):
        eff, f = in_model[i]
        without = _without(fitter, cfg0, axis, in_model, i)
        earns = 2.0 * (without.nll - cur.nll) - f.n_fitted * math.log(n_obs)
        if earns < opt.min_score:
            log.info(
                "%s no longer earns its place beside %s (BIC %.1f): dropped",
                eff.name,
                ", ".join(e.name for j, (e, _) in enumerate(in_model) if j != i),
                earns,
            )
            del in_model[i], findings[i]
            fitter.hold = frozenset(p for e, _ in in_model for p in e.owns)
            cfg, cur = _with_effects(cfg0, axis, in_model), without
    return cfg, cur


def _order_by_gap_closed(
    fitter: Fitter,
    cfg0: SimConfig,
    axis: str,
    in_model: list[tuple[catalogue.Effect, EffectFit]],
    findings: list[Finding],
    P: np.ndarray,
    cells: np.ndarray,
    dof: np.ndarray,
    gap_all: float,
) -> None:
    """Several effects are reported in the order of the gap each closes on the same cells (all
    the gap's): the refined model's gap against the gap without that effect, the others and
    the noise levels staying fitted. Each finding's ``gap_before_db`` / ``gap_after_db``
    become those two."""
    for i in range(len(in_model)):
        without = _without(fitter, cfg0, axis, in_model, i)
        findings[i].gap_before_db, findings[i].gap_after_db = (
            gap_db(P, without.S, cells, dof),
            gap_all,
        )
    order = sorted(
        range(len(findings)), key=lambda i: -(findings[i].gap_before_db - findings[i].gap_after_db)
    )
    findings[:] = [findings[i] for i in order]
    in_model[:] = [in_model[i] for i in order]


#: how far (dB) the refined model's simulated run may sit from the record beyond its expected
#: spectrum's gap before the two measures are said to disagree
SIM_AGREEMENT_DB = 3.0

#: where no band departs (after a first effect), a candidate is named only on this many times
#: ``min_score`` of BIC and if it closes at least ``tol_db`` where it acts
QUIET_SCORE_FACTOR = 5.0

#: a fitted parameter within this share of its prior's (log) width of a bound sits at it
BOUND_SHARE = 0.005


def _at_bound(effect: catalogue.Effect, params: dict[str, float]) -> list[str]:
    """The fitted parameters at a bound of their prior that is not a physical limit."""
    out = []
    for p in effect.fit_params:
        v = params.get(p.name)
        if v is None or not math.isfinite(v):
            continue
        t = to_unit(p, v)
        if (t <= BOUND_SHARE and p.limit != "lo") or (t >= 1 - BOUND_SHARE and p.limit != "hi"):
            out.append(
                f"{p.name} = {v:.4g} at {'lower' if t <= BOUND_SHARE else 'upper'} bound "
                f"{p.lo if t <= BOUND_SHARE else p.hi:g}"
            )
    return out


def _final_fit(
    fitter: Fitter,
    effect: catalogue.Effect,
    cfg: SimConfig,
    evidence: Evidence,
    f: EffectFit,
    base_nll: float,
    n_obs: int,
) -> EffectFit:
    """``f`` refined again with its uncertainties (and the knee's envelope), scored against
    ``base_nll``; ``f`` itself where the refinement finds nothing better."""
    final = fitter.fit(effect, cfg, evidence, start=f.params)
    if final is None or final.nll > f.nll + 1e-6:
        return f
    final.score = bic_score(final, base_nll, n_obs)
    return fitter.held_envelope(effect, cfg, evidence, final)


def _moved(
    S: np.ndarray, scales: dict[str, float], cur: NuisanceFit, base_ms: Any, tol_db: float
) -> np.ndarray:
    """The cells an effect's model ``S`` moves by more than ``tol_db``: against the model without
    it at the same noise levels ``scales`` (a refitted noise level moves every band a little, and
    is no effect's doing), with the unit's knee as fitted without it (``cur``: an effect that
    sets the corner moves it)."""
    same = scales | {k: cur.scales[k] for k in SHAPE_KEYS if k in cur.scales}
    return np.abs(10.0 * np.log10(S / base_ms.total(same))) > tol_db


def _pair_that_closes(
    fitter: Fitter,
    cfg: SimConfig,
    cur: NuisanceFit,
    fits: list[EffectFit],
    evidence: Evidence,
    flags: np.ndarray,
    base_ms: Any,
    n_obs: int,
    opt: GapOptions,
    P: np.ndarray,
    dof: np.ndarray,
) -> list[tuple[EffectFit, np.ndarray, float, float]]:
    """Two effects that together close what neither closes alone, or nothing.

    Where two effects overlap in frequency (a pickup line inside a loop peak that a delay
    raises; a mount mode beside a scale-factor change of the loop gain), each one fitted alone
    on the nominal model has to bend to cover the other's share too, and closes too little
    where it acts to be named; the sequential search then names neither. Each pair of the
    ``opt.pair_top`` leading candidates is fitted as the first at its fit and the second fitted
    on top; the pair is named (the first, then the second) when together they close the share
    a single effect must, and the second earns its place on the first by the BIC. The joint
    re-fit that follows (``_refit_jointly``) re-fits the first beside the second and drops
    either one that no longer earns its place. Returns the two as (fit, moved cells, gap
    before, gap after) for the caller to name, or []."""
    leaders = [f for f in fits if f.score >= opt.min_score][: opt.pair_top]
    best: tuple[float, list[tuple[EffectFit, np.ndarray, float, float]]] | None = None
    held = fitter.hold
    for i, a in enumerate(leaders):
        eff_a = catalogue.get(a.effect)
        for b in leaders[i + 1 :]:
            eff_b = catalogue.get(b.effect)
            fitter.hold = held | frozenset(eff_a.owns)
            try:
                fb = fitter.fit(eff_b, a.cfg, evidence, start=b.params)
                if fb is not None:
                    fb = fitter.held_envelope(eff_b, a.cfg, evidence, fb)
            finally:
                fitter.hold = held
            if fb is None or bic_score(fb, a.nll, n_obs) < opt.min_score:
                continue
            moved = _moved(fb.S, fb.scales, cur, base_ms, opt.tol_db)
            where = _where_it_acts(flags, moved)
            g0, g_a, g2 = (
                gap_db(P, cur.S, where, dof),
                gap_db(P, a.S, where, dof),
                gap_db(P, fb.S, where, dof),
            )
            need = max(opt.min_closed_db, opt.min_closed_share * g0)
            log.info(
                "pair %s + %s closes %.2f of %.2f dB where it acts (%d cells)",
                a.effect,
                b.effect,
                g0 - g2,
                g0,
                int(where.sum()),
            )
            if g0 - g2 >= need and (best is None or g2 < best[0]):
                fa = _final_fit(fitter, eff_a, cfg, evidence, a, cur.nll, n_obs)
                fb.score = bic_score(fb, fa.nll, n_obs)
                moved_a = _moved(fa.S, fb.scales, cur, base_ms, opt.tol_db)
                best = (g2, [(fa, moved_a, g0, g_a), (fb, moved, g_a, g2)])
    return [] if best is None else best[1]


def _where_it_acts(flags: np.ndarray, moved: np.ndarray) -> np.ndarray:
    """The cells on which a candidate is judged: those it moves by more than the tolerance, and
    the departing cells within the span of bands it moves (any channel). A line moves one band
    and is judged there, not diluted by another effect's departures an octave away; a broad
    effect is judged on every departure it could reach."""
    cols = np.flatnonzero(moved.any(axis=0))
    if len(cols) == 0:
        return flags.copy()
    span = np.zeros(moved.shape[1], bool)
    span[cols[0] : cols[-1] + 1] = True
    return moved | (flags & span[None, :])


def _rounded_intervals(d: dict[str, tuple[float, float]]) -> dict[str, list[float | None]]:
    return {k: [float(f"{v:.5g}") if math.isfinite(v) else None for v in iv] for k, iv in d.items()}


#: the narrow excesses measured as sinusoids on the record, at most this many, each searched
#: within this many Welch bins of the bin it peaks in
MAX_LINES, LINE_SEARCH_BINS = 6, 1.5


def _measured_lines(
    rec: Record, grid: Grid, S: np.ndarray, located: list[Band]
) -> list[MeasuredLine]:
    """Each excess (largest first) measured as a sinusoid on its channel's record
    (``lines.refine_line``), the model's level in its band as the noise around it."""
    out = []
    for b in [b for b in located if b.deviation_db > 0][:MAX_LINES]:
        i = rec.channels.index(b.channel)
        band = int(np.clip(np.searchsorted(grid.band_hi_hz, b.peak_hz), 0, grid.n_bands - 1))
        out.append(
            refine_line(
                rec.data[i], rec.rate_hz, b.peak_hz, LINE_SEARCH_BINS * grid.df, float(S[i, band])
            )
        )
    return out


def _detect_steps(
    rec: Record, cfg: SimConfig, window_s: float = 2.0, template_s: float = 60.0
) -> tuple[list[Step], str | None]:
    """Steps in the channel that shows a unit autocollimator-offset step best (its D over its
    noise), among channels where that step reads as a step; sizes in radians of the offset."""
    if rec.duration_s < 8 * window_s:
        return [], None
    step_at = int(round(window_s * rec.rate_hz))
    resp = step_response(
        cfg,
        rec.mode,
        f"nac_{rec.axis}",
        rec.channels,
        rec.rate_hz,
        min(template_s, rec.duration_s / 2) + window_s,
        window_s,
    )
    best: tuple[float, str, np.ndarray, np.ndarray] | None = None
    for c, x, r in zip(rec.channels, rec.data, resp):
        if not step_like(r, rec.rate_hz, step_at, window_s=window_s):
            continue
        g = template_gain(r, rec.rate_hz, step_at=step_at, window_s=window_s)
        _, d = window_difference(x - x.mean(), step_at, max(1, step_at // 20))
        snr = abs(g) / max(robust_scale(d), 1e-300)
        if best is None or snr > best[0]:
            best = (snr, c, x, r)
    if best is None:
        return [], None
    _, c, x, r = best
    steps, _ = find_steps(x, rec.rate_hz, template=r, step_at=step_at, window_s=window_s)
    return steps, c


def _model_makes_steps(cfg: SimConfig, axis: str) -> bool:
    ac = cfg.autocollimator.get(axis)
    return bool(ac and ac.offset_jump_urad > 0)


def simulate_record(
    cfg: SimConfig, rec: Record, seed: int, out: Path | None = None, note: str = ""
) -> np.ndarray:
    """The model with the measured run's channels, rate, duration and ADC ranges; written to
    ``out`` as an fbs-run file when given. Returns (n_channels, n) volts."""
    # only the recorded channels: the part of the rig they depend on, the same numbers (simhw.reduction)
    sim = Simulator(cfg, rate_hz=rec.rate_hz, seed=seed, mode=rec.mode, channels=rec.channels)
    for c, q, x in zip(rec.channels, rec.lsb_V, rec.data):
        sim.set_range(c, _adc_range(q, float(np.max(np.abs(x))), cfg.sampling.adc_bits))
    n = rec.data.shape[1]
    writer = None
    if out is not None:
        meta = {
            "configuration": to_dict(cfg),
            "seed": seed,
            "source": f"fbs gap: {note}",
            "measured_file": str(rec.path),
            "calibration": {},
            "provenance": provenance.offline("fbs-gap-model", None),
        }
        writer = RunWriter(
            out,
            rig="fbs-gap-model",
            mode=rec.mode,
            rate_hz=rec.rate_hz,
            channels={c: "V" for c in rec.channels},
            axis=rec.axis,
            meta=meta,
            overwrite=True,
        )
    try:
        chunks = []
        per = int(round(10 * rec.rate_hz))
        done = 0
        while done < n:
            k = min(per, n - done)
            block = sim.advance(k)
            v = block.volts
            chunks.append(v)
            if writer is not None:
                writer.append({c: v[:, j] for j, c in enumerate(rec.channels)})
            done += k
    except BaseException as e:
        if writer is not None:
            writer.close(f"aborted: {e}")
        raise
    if writer is not None:
        writer.close()
    return np.concatenate(chunks).T


def _range_from_lsb(q: float, bits: int) -> float | None:
    """The ADC range whose LSB is ``q`` (2 range / 2^bits), if it is one the converter has."""
    if q > 0:
        full = q * 2 ** (bits - 1)
        for r in ADC_RANGES_V:
            if abs(r - full) <= 0.01 * r:
                return r
    return None


def _adc_range(q: float, peak: float, bits: int) -> float:
    """The measured channel's ADC range from its LSB; for data not on a grid, the finest range
    that holds its peak with margin."""
    fits = [r for r in ADC_RANGES_V if r >= 1.5 * peak]
    return _range_from_lsb(q, bits) or (min(fits) if fits else max(ADC_RANGES_V))


def analyse(
    path: str | Path,
    *,
    axis: str | None = None,
    options: GapOptions | None = None,
    report_dir: str | Path | None = None,
) -> GapResult:
    """Run the whole workflow on one file; with ``report_dir`` also write the model files and plots."""
    t_start = time.perf_counter()
    opt = options or GapOptions()
    rec = load_record(path, axis)
    grid = make_grid(rec.rate_hz, rec.data.shape[1])
    _, p_bins = bin_spectra(rec.data, grid)
    P = grid.band_mean(p_bins)
    quant = np.array([quantization_psd(q, rec.rate_hz) for q in rec.lsb_V])
    cfg0 = catalogue.nominal(load_config(opt.sim_config) if opt.sim_config is not None else None)
    cfg0 = found_pickoff_lines(cfg0, rec.axis, rec.channels, p_bins, grid)
    model = SpectralModel(grid, rec.channels, rec.mode, rec.axis, quant)
    # the channels' Whittle terms weighted by their coherent multiplicity (grid.channel_weights):
    # the likelihood of one measurement, not of four independent ones
    weights = channel_weights(rec.data, grid)
    fitter = Fitter(model, P, grid.dof * weights, rec.axis)
    base = fitter.base(cfg0)
    steps, step_channel = _detect_steps(rec, cfg0)
    n_obs = max(int(round(float(weights.sum()))), 1)

    cfg, cur = cfg0, base
    findings: list[Finding] = []
    cells = np.zeros(P.shape, bool)
    first_located: list[Band] = []
    first_candidates: list[dict[str, Any]] = [{"effect": "none", "score": 0.0}]
    significant = False
    unexplained = False
    remaining: list[Band] = []
    remaining_steps: list[Step] = []
    partial: list[dict[str, Any]] = []
    named: set[str] = set()
    in_model: list[tuple[catalogue.Effect, EffectFit]] = []
    for it in range(opt.max_effects + 1):
        flags = departures(P, cur.S, grid.dof, alpha=opt.alpha, tol_db=opt.tol_db)
        unexplained_steps = bool(steps) and not _model_makes_steps(cfg, rec.axis)
        ratio = p_bins / cur.S[:, grid.band_of_bin]
        located = bands(flags, P, cur.S, grid, rec.channels, ratio)
        if it == 0:
            first_located = located
            significant = bool(flags.any() or unexplained_steps)
        cells |= flags
        # Quiet: no band departs and no step is left. A record that starts quiet is nominal. Once
        # an effect is in the model, the bands are no longer the only evidence: a second effect
        # whose joint evidence over many bands is strong (the BIC) and that closes the gap where
        # it acts is named even where no single band departs (a moderate flicker beside a mount
        # mode reads +1 to +3 dB over an octave of 1/24-octave bands, each within its scatter).
        quiet = not (flags.any() or unexplained_steps)
        if quiet and (it == 0 or not opt.look_when_quiet):
            break
        if not quiet:
            remaining, remaining_steps = located, (steps if unexplained_steps else [])
        if it == opt.max_effects:
            unexplained = not quiet
            break
        # Excesses where the measurement exceeds the model, at bin resolution; those as narrow
        # as the window makes a sinusoid are lines, their frequency measured on the record.
        measured = _measured_lines(rec, grid, cur.S, located)
        peaks = [b.peak_hz for b in located if b.deviation_db > 0]
        peaks[: len(measured)] = [m.freq_hz if m.is_line else p for m, p in zip(measured, peaks)]
        evidence = Evidence(
            rec.duration_s,
            peaks,
            [s.size / URAD for s in steps],
            [b.peak_hz for b in located if b.deviation_db < 0],
            [(m.freq_hz, m.sigma_hz) for m in measured if m.is_line],
        )
        # Screen every effect at its starting points, refine the leaders, then the winner's errors.
        screened: list[tuple[EffectFit, Any]] = []
        for eff in catalogue.catalogue().values():
            if eff.name == "none" or (eff.name in named and not eff.repeatable):
                continue
            t0, n0 = time.perf_counter(), fitter.evaluations
            f = fitter.fit(eff, cfg, evidence, refine=False, errors=False)
            log.debug(
                "screened %s: %d evaluations, %.2f s",
                eff.name,
                fitter.evaluations - n0,
                time.perf_counter() - t0,
            )
            if f is not None:
                screened.append((f, eff))
        screened.sort(key=lambda fe: fe[0].nll)
        fits: list[EffectFit] = []
        for rank, (f, eff) in enumerate(screened):
            # refined: the leaders; where nothing departs, only a leader already within reach of
            # being named (a refinement gains a few BIC units, not tens)
            leader = rank < opt.refine_top
            if leader and (not quiet or bic_score(f, cur.nll, n_obs) > opt.min_score / 2):
                refined = fitter.fit(eff, cfg, evidence, errors=False, start=f.params)
                f = refined if refined is not None and refined.nll <= f.nll else f
            f.score = bic_score(f, cur.nll, n_obs)
            fits.append(f)
        fits.sort(key=lambda f: -f.score)
        candidates = [f.summary for f in fits] + [{"effect": "none", "score": 0.0}]
        candidates.sort(key=lambda c: -c["score"])
        if it == 0:
            first_candidates = candidates
        # The best-scoring candidate that also closes a material share of the gap where it acts
        # (the bands located in this pass, and those where it moves the model by more than the
        # tolerance: a departure the noise nuisance half absorbed is located only in its
        # strongest bands, and those few partly by their own scatter).
        chosen: tuple[EffectFit, np.ndarray, float, float] | None = None
        partial = []
        base_ms = fitter.model(cfg)
        # Steps in the time domain are a shape no spectrum-only effect has: while the model makes
        # none, the candidates that make them are judged first (a broad noise can mimic their
        # spectrum, never their steps).
        order = sorted(
            fits, key=lambda f: not (unexplained_steps and _model_makes_steps(f.cfg, rec.axis))
        )
        for f in order:
            if f.score < opt.min_score:
                continue
            if quiet and (
                f.score < QUIET_SCORE_FACTOR * opt.min_score
                or _at_bound(catalogue.get(f.effect), f.params)
            ):
                # where nothing departs, the evidence must be strong, and a form that reaches the
                # data only at its extreme is no finding
                continue
            # refined again, with its uncertainties, before it is judged
            f = _final_fit(fitter, catalogue.get(f.effect), cfg, evidence, f, cur.nll, n_obs)
            moved = _moved(f.S, f.scales, cur, base_ms, opt.tol_db)
            where = _where_it_acts(flags, moved)
            g0, g1 = gap_db(P, cur.S, where, grid.dof), gap_db(P, f.S, where, grid.dof)
            # steps seen in the time domain are a departure of their own: an effect that makes
            # them in the model explains them, whatever an earlier effect left of their spectrum
            explains_steps = unexplained_steps and _model_makes_steps(f.cfg, rec.axis)
            need = max(opt.tol_db if quiet else opt.min_closed_db, opt.min_closed_share * g0)
            if explains_steps or g0 - g1 >= need:
                chosen = (f, moved, g0, g1)
                break
            log.info(
                "%s %s wins on the score (%.1f) but closes only %.2f of %.2f dB where it acts (%d cells): "
                "not named",
                f.effect,
                f.params,
                f.score,
                g0 - g1,
                g0,
                int(where.sum()),
            )
            partial.append(
                {
                    "effect": f.effect,
                    "score": round(f.score, 2),
                    "gap_closed_db": round(g0 - g1, 3),
                    "of_db": round(g0, 3),
                }
            )
        if chosen is None and quiet:
            partial = []
            break
        accepted = [chosen] if chosen is not None else []
        if not accepted:
            accepted = _pair_that_closes(
                fitter, cfg, cur, fits, evidence, flags, base_ms, n_obs, opt, P, grid.dof
            )
        if not accepted:
            partial = partial or [
                {"effect": f.effect, "score": round(f.score, 2)} for f in fits[:2] if f.score > 0
            ]
            unexplained = True
            break
        partial = []
        for best, moved, g0, g1 in accepted:
            winner = catalogue.get(best.effect)
            runner: dict[str, Any] = next(
                (c for c in candidates if c["effect"] != best.effect),
                {"effect": "none", "score": 0.0},
            )
            cells |= moved
            findings.append(
                Finding(
                    best.effect,
                    best.params,
                    best.errors,
                    best.score,
                    runner["effect"],
                    best.score - runner["score"],
                    g0,
                    g1,
                    located,
                    candidates,
                    best.intervals,
                )
            )
            log.info(
                "named %s (score %.1f, %.1f over %s): %s",
                best.effect,
                best.score,
                best.score - runner["score"],
                runner["effect"],
                best.params,
            )
            named.add(best.effect)
            fitter.hold |= frozenset(winner.owns)
            cfg, cur = best.cfg, NuisanceFit(best.scales, best.nll, best.S)
            in_model.append((winner, best))
        if len(in_model) > 1:
            cfg, cur = _refit_jointly(
                fitter, cfg0, rec.axis, in_model, findings, evidence, n_obs, opt
            )

    # A parameter fitted at a bound of its prior (not one that is a physical limit) says the
    # effect's form does not reach the data: it is kept as the best partial candidate, and the
    # departure stays unexplained.
    for fd in findings:
        fd.at_bound = _at_bound(catalogue.get(fd.effect), fd.parameters)
        if fd.at_bound:
            log.info(
                "%s is fitted at the bound of its prior (%s): not an explanation",
                fd.effect,
                ", ".join(fd.at_bound),
            )
            if not unexplained:
                unexplained = True
                remaining = first_located
                remaining_steps = steps if (steps and not _model_makes_steps(cfg, rec.axis)) else []
            partial.append(
                {"effect": fd.effect, "score": round(fd.score, 2), "at_bound": fd.at_bound}
            )
    cfg_before = apply_nuisance(cfg0, rec.axis, base.scales)
    cfg_after = apply_nuisance(cfg, rec.axis, cur.scales)
    spectra = {"measured": P, "model_before_expected": base.S, "model_after_expected": cur.S}
    # The gap is measured against each model's expected spectrum: what its simulation converges
    # to (exactly: test_model.py), without one realization's scatter, which for rare events such
    # as offset jumps would dominate. The simulated runs are the report's, with their own gaps.
    gap_before = gap_db(P, base.S, cells, grid.dof)
    gap_after = gap_db(P, cur.S, cells, grid.dof)
    if len(in_model) > 1:
        _order_by_gap_closed(
            fitter, cfg0, rec.axis, in_model, findings, P, cells, grid.dof, gap_after
        )
    sim_gaps: tuple[float, float] | None = None
    if report_dir is not None:
        out = Path(report_dir)
        make_folder(out)
        sim_b = simulate_record(
            cfg_before, rec, opt.seed, out / "model_before.h5", "nominal model, noise levels fitted"
        )
        sim_a = simulate_record(
            cfg_after,
            rec,
            opt.seed + 1,
            out / "model_after.h5",
            "refined model: " + (", ".join(f.effect for f in findings) or "nothing added"),
        )
        spectra["model_before"] = band_spectra(sim_b, grid)
        spectra["model_after"] = band_spectra(sim_a, grid)
        sim_gaps = (
            gap_db(P, spectra["model_before"], cells),
            gap_db(P, spectra["model_after"], cells),
        )
        # The two measures must agree: the expected spectrum is what the simulation converges to,
        # so a simulated run far from it (beyond one realization's scatter, ~1 dB) says the
        # expected spectrum is no prediction of that model (a loop on the edge of stability).
        if sim_gaps[1] > gap_after + SIM_AGREEMENT_DB:
            rec.warnings.append(
                f"the refined model's simulated run is {sim_gaps[1]:.1f} dB from the "
                f"record where its expected spectrum is {gap_after:.1f} dB: its "
                "figures are not to be trusted"
            )
    result = GapResult(
        str(rec.path),
        rec.axis,
        rec.mode,
        rec.rate_hz,
        rec.duration_s,
        rec.channels,
        significant,
        findings,
        first_located,
        steps,
        step_channel,
        gap_before,
        gap_after,
        first_candidates,
        base.scales,
        cur.scales,
        rec.warnings,
        unexplained,
        grid,
        spectra,
        cfg_before,
        cfg_after,
        sim_gaps=sim_gaps,
        remaining=remaining if unexplained else [],
        remaining_steps=remaining_steps if unexplained else [],
        partial=partial if unexplained else [],
    )
    result.elapsed_s = time.perf_counter() - t_start
    if report_dir is not None:
        from procedures.analysis.gap.report import write_report

        write_report(result, Path(report_dir))
    return result
