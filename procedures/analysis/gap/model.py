"""Expected spectra of the simulated rig, computed exactly from its linear model.

The model-gap workflow needs the spectrum the model *predicts* for many candidate
configurations, far faster than simulating each. ``simhw`` is one linear state-space model
driven by noise inputs held over each step (docs/simhw.md section 1), so its output spectrum
is exact in closed form:

    S_y(f) = sum_i |H_yi(e^(j 2 pi f dt))|^2 S_i(f)              (linear system, [BP] 5.2)

with ``H = C (zI - A_d)^-1 B_d + D`` the discrete plant at the internal step ``dt`` and
``S_i`` each input's spectrum as the plant sees it (``simhw.noise`` sources report their own).
The recording chain follows: the 3-pole anti-alias filter ``|AA|^2`` at the internal rate,
then decimation, which folds the internal spectrum onto 0..fs/2 (aliases f, fs - f, ...), and
the ADC's white quantization floor ``q^2 / (6 fs)`` one-sided (App. A.7). Deterministic
sinusoids (pickoff lines, electrical pickup) are not spectra: their expected Welch estimate
is the Hann window's kernel ``2 (A/2)^2 |W(f - f0)|^2 / (fs sum w^2)`` around each line.

The spectrum is returned in parts so the workflow can scale noise levels it treats as
nuisance parameters (the axis's autocollimator noise and gyro pickoff noise, and each of the
axis gyro's pickoff lines: ``line0``, ``line1``, ... in the data sheet's order) without
recomputing the plant.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.signal

from procedures.analysis.gap.grid import Grid
from simhw.config import SimConfig
from simhw.plant import RelayState, build_plant, discretize
from simhw.sampling import anti_alias_sos, internal_rate
from simhw.simulator import Sources, ac_knee, ac_white_psd

#: Parts of the spectrum whose level is a nuisance parameter: the axis's autocollimator noise
#: ("ac": the response to its white level, times the unit's 1/f knee ``ac_knee`` when the axis
#: has a primary autocollimator; the azimuth autocollimator's pure 1/f is "ac_flicker"), and
#: the gyro pickoff's white noise; the axis gyro's pickoff lines are nuisance parts of their own
#: (``line_part``). An excess 1/f from an old configuration's ``extra_flicker_corner_hz``
#: ("ac_excess") moves with "ac".
PARTS = ("ac", "ac_flicker", "ac_excess", "pickoff", "fixed")

#: the nuisance keys of the autocollimator's 1/f knee (DESIGN.md section 8): its corner (Hz),
#: its form (0 = max(1, r), 1 = 1 + r) and its slope, r = (corner / f)^slope
SHAPE_KEYS = ("ac_corner_hz", "ac_knee", "ac_slope")


#: K(f) of the nominal unit's 1/f knee: the one the simulator realizes (DESIGN.md section 8)
knee = ac_knee


def knee_gradient(
    f: np.ndarray, corner_hz: float, form: float, slope: float
) -> tuple[np.ndarray, ...]:
    """dK/d ln(corner), dK/d form, dK/d slope of :func:`knee` (K = form (1 + r) + (1 - form)
    max(1, r), r = (corner/f)^slope)."""
    ln = np.log(corner_hz / np.asarray(f, float))
    r = np.exp(slope * ln)
    dk_dr = form + (1.0 - form) * (r > 1.0)
    return dk_dr * slope * r, np.minimum(1.0, r), dk_dr * r * ln


def line_part(k: int) -> str:
    """The part of the axis gyro's ``k``-th pickoff line (its power is a nuisance scale)."""
    return f"line{k}"


def part_of(input_name: str, kind: str, axis: str) -> str | None:
    """Which part of the spectrum a noise source feeds (None: the primary autocollimator's 1/f
    bank, which the analytic knee replaces)."""
    if input_name == f"nac_{axis}" and kind == "WhiteNoise":
        return "ac"
    if input_name == f"nac_{axis}" and kind == "FlickerNoise":
        return "ac_flicker" if axis == "Z" else None
    if input_name == f"nac_{axis}" and kind == "ExcessFlickerNoise":
        return "ac_excess"
    if input_name == f"np_{axis}" and kind == "WhiteNoise":
        return "pickoff"
    return "fixed"


def ac_shape(cfg: SimConfig, axis: str) -> tuple[float, float, float]:
    """The configuration's own 1/f knee of the axis autocollimator: (corner Hz, form, slope)."""
    ac = cfg.autocollimator[axis]
    return ac.flicker_corner_hz, float(ac.flicker_knee), float(ac.flicker_slope)


def apply_nuisance(cfg: SimConfig, axis: str, scales: dict[str, float]) -> SimConfig:
    """A copy of ``cfg`` whose noise is the fitted nuisance: the autocollimator's white PSD
    scaled by ``ac`` with the fitted knee (``SHAPE_KEYS``: corner, form, slope; the NEA follows
    from them, ``simhw.simulator.ac_white_psd``); the azimuth autocollimator's 1/f by
    ``ac_flicker``; the pickoff's white PSD (the quoted rms's variance less the lines',
    ``simhw.simulator.pickoff_white_psd``) by ``pickoff``; each line's power by its part's."""
    cfg = cfg.copy()
    s_w, s_np = scales.get("ac", 1.0), scales.get("pickoff", 1.0)
    if axis in cfg.autocollimator:
        ac = cfg.autocollimator[axis]
        fc0, form0, slope0 = ac_shape(cfg, axis)
        w, z = ac.control_filter_rad_per_s, ac.control_filter_zeta
        white = ac_white_psd(ac.nea_urad, fc0, w, z, knee=form0, slope=slope0)
        fc = scales.get("ac_corner_hz", fc0)
        form, slope = scales.get("ac_knee", form0), scales.get("ac_slope", slope0)
        moved = ac_white_psd(ac.nea_urad, fc, w, z, knee=form, slope=slope)
        ac.nea_urad *= math.sqrt(s_w * white / moved)
        ac.flicker_corner_hz, ac.flicker_knee, ac.flicker_slope = fc, form, slope
    elif axis == "Z":
        cfg.azimuth.nea_urad *= math.sqrt(scales.get("ac_flicker", 1.0))
    g = cfg.gyro[axis]
    white = max(
        s_np * (g.pickoff_noise_rms_urad**2 - sum(a * a / 2 for _, a in g.pickoff_lines)), 0.0
    )
    g.pickoff_lines = [
        [f0, a * math.sqrt(scales.get(line_part(k), 1.0))]
        for k, (f0, a) in enumerate(g.pickoff_lines)
    ]
    g.pickoff_noise_rms_urad = math.sqrt(white + sum(a * a / 2 for _, a in g.pickoff_lines))
    return cfg


@dataclass
class ModelSpectrum:
    """Band spectra of the analysed channels, (n_channels, n_bands) per part, and the
    configuration's own 1/f knee (``shape``: corner, form, slope) at the bands' centres ``f``.
    The "ac" part is the response to the autocollimator's white level; its total is that part
    times the knee (``knee``), at the shape given in the scales (``SHAPE_KEYS``) or the
    configuration's."""

    channels: tuple[str, ...]
    parts: dict[str, np.ndarray]
    f: np.ndarray | None = None
    shape: tuple[float, float, float] | None = None
    #: the closed loop is stable: a model whose loop diverges has no stationary spectrum, and
    #: could not have made a record (its "expected spectrum" is no prediction of anything)
    stable: bool = True

    def ac_knee(self, scales: dict[str, float] | None = None) -> np.ndarray | float:
        """K(f) of the bands at the scales' knee (or the configuration's)."""
        if self.f is None or self.shape is None:
            return 1.0
        scales = scales or {}
        fc, form, slope = (scales.get(k, d) for k, d in zip(SHAPE_KEYS, self.shape))
        return knee(self.f, fc, form, slope)

    def total(self, scales: dict[str, float] | None = None) -> np.ndarray:
        scales = scales or {}
        out = np.array(self.parts["fixed"], float)
        for name, part in self.parts.items():
            if name == "fixed":
                continue
            s = scales.get(name, 1.0) if name != "ac_excess" else scales.get("ac", 1.0)
            out = out + part * s * (self.ac_knee(scales) if name == "ac" else 1.0)
        return out


#: Equivalent viscous damping of a Dahl bearing under the rig's random motion, per unit
#: k / To (N m s rad): c_eq = DAHL_DAMPING * k / To. Dahl's slope eta (T -+ To)^2 differs
#: going up and down by a fraction of order |T| / To, so even microradian motion dissipates
#: energy, which fills the dip. Calibrated on simhw's Dahl bearing at the data sheet's noise
#: levels (k 300-1500 N m/rad, To 0.016-0.05 N m: 2.1e-5 to 2.4e-5; docs/gap.md). Larger motion
#: than the data sheet's reads as a smaller fitted To.
DAHL_DAMPING = 2.25e-5


def linearized(cfg: SimConfig) -> SimConfig:
    """The plant the spectra see: each Dahl bearing as its spring eta To^2 plus the equivalent
    damping of its hysteresis (random-input linearization). Without a Dahl bearing, ``cfg``
    itself (read only: a copy costs more than the rest of a model evaluation)."""
    if not any(b.model == "dahl" for b in cfg.bearing.values()):
        return cfg
    out = cfg.copy()
    for axis, b in out.bearing.items():
        if b.model == "dahl":
            k = b.eta_per_Nm * b.To_Nm**2
            b.model, b.stiffness_Nm_per_rad = "spring", k
            out.platform[axis].extra_damping_Nms += DAHL_DAMPING * k / b.To_Nm
    return out


def relays_for(mode: int) -> RelayState:
    return RelayState(mode=mode, spin=1.0 if mode >= 2 else 0.0)


def _aliases(f: np.ndarray, fs: float, m: int) -> list[np.ndarray]:
    """Internal-rate frequencies folding onto each output frequency ``f`` (NaN where none)."""
    nyq_int = fs * m / 2
    out = []
    for k in range(m + 1):
        for sign in (1, -1):
            if k == 0 and sign < 0:
                continue
            fa = k * fs + sign * f
            ok = (fa > 0) & (fa < nyq_int)
            if ok.any():
                out.append(np.where(ok, fa, np.nan))
    return out


def frequency_response(
    Ad: np.ndarray, Bd: np.ndarray, C: np.ndarray, D: np.ndarray, z: np.ndarray
) -> np.ndarray:
    """H(z) = C (zI - Ad)^-1 Bd + D at each z: (n_z, n_out, n_in), by a batched direct solve
    (for plants whose modes are too ill-conditioned for ``zoh_response_modal``)."""
    n = Ad.shape[0]
    return C @ np.linalg.solve(z[:, None, None] * np.eye(n) - Ad, Bd) + D


def _dirichlet(x: np.ndarray, n: int) -> np.ndarray:
    """sum_{m<n} e^(-j 2 pi x m / n) for real x (bins): e^(-j pi x (n-1)/n) sin(pi x) / sin(pi x / n)."""
    x = np.asarray(x, float)
    s = np.sin(np.pi * x / n)
    small = np.abs(s) < 1e-12
    ratio = np.where(small, float(n), np.sin(np.pi * x) / np.where(small, 1.0, s))
    return np.exp(-1j * np.pi * x * (n - 1) / n) * ratio


def zoh_response_modal(
    A: np.ndarray,
    B: np.ndarray,
    C: np.ndarray,
    D: np.ndarray,
    dt: float,
    z: np.ndarray,
    max_cond: float = 1e11,
) -> np.ndarray | None:
    """The exact ZOH discretization's frequency response from the continuous modes, without a
    matrix exponential: with A = V diag(l) V^-1, A_d = V diag(e^(l dt)) V^-1 and
    B_d = V diag((e^(l dt) - 1) / l) V^-1 B, so

        H(z) = C V diag(phi(l) / (z - e^(l dt))) V^-1 B + D,   phi(l) = (e^(l dt) - 1) / l.

    A is balanced first (a diagonal similarity, ``scipy.linalg.matrix_balance``): the plant's
    states span radians to volts, and unbalanced their eigenvectors' condition reaches 1e12
    where balanced it is 1e4. None when the eigenvectors are still too ill-conditioned to trust
    (``max_cond``)."""
    A, (scale, _) = scipy.linalg.matrix_balance(A, permute=False, separate=True)
    B, C = B / scale[:, None], C * scale[None, :]
    lam, V = np.linalg.eig(A)
    if not np.all(np.isfinite(lam)) or np.linalg.cond(V) > max_cond:
        return None
    ed = np.exp(lam * dt)
    small = np.abs(lam * dt) < 1e-8
    phi = np.where(small, dt * (1 + lam * dt / 2), np.expm1(lam * dt) / np.where(small, 1.0, lam))
    CV = C @ V
    VB = np.linalg.solve(V, B) * phi[:, None]
    G = 1.0 / (z[:, None] - ed[None, :])
    # sum over modes n of G[z, n] CV[o, n] VB[n, i]: one matrix product with the mode terms
    # (n, o i) rather than one small product per frequency (a third of the time)
    n_out, n_in = CV.shape[0], VB.shape[1]
    W = (CV.T[:, :, None] * VB[:, None, :]).reshape(len(ed), n_out * n_in)
    return (G @ W).reshape(len(z), n_out, n_in) + D


def coupled_states(A: np.ndarray, B: np.ndarray, C: np.ndarray) -> np.ndarray:
    """The states an input reaches and an output sees, by the sparsity of A, B and C (Kalman's
    decomposition, structurally). The rest change nothing of H(z) = C (zI - A)^-1 B: a state no
    input reaches through A stays at rest, and one from which no path leads to an output is never
    seen, so H is that of the plant reduced to these states, exactly. The Y channels see 25 of
    the rig's 39 states in Mode 3 (the other axes' loops are apart), and a response's cost is its
    modes times its frequencies."""
    edge = A != 0  # edge[i, j]: state j drives state i
    reach = np.any(B != 0, axis=1)
    while True:
        grown = reach | np.any(edge[:, reach], axis=1)
        if np.array_equal(grown, reach):
            break
        reach = grown
    seen = np.any(C != 0, axis=0)
    while True:
        grown = seen | np.any(edge[seen, :], axis=0)
        if np.array_equal(grown, seen):
            break
        seen = grown
    return np.flatnonzero(reach & seen)


def hann_line_kernel(grid: Grid, f0: float, amplitude: float) -> tuple[np.ndarray, np.ndarray]:
    """Expected one-sided Welch density of ``amplitude sin(2 pi f0 t)`` at the analysed bins near
    f0: positions into ``grid.bins`` and values. The periodic Hann window
    0.5 - 0.25 e^(j 2 pi m/N) - 0.25 e^(-j 2 pi m/N) transforms to
    W(x) = 0.5 D(x) - 0.25 D(x - 1) - 0.25 D(x + 1), D the Dirichlet kernel, sum w^2 = 3N/8."""
    k0 = f0 / grid.df
    near = np.flatnonzero(np.abs(grid.bins - k0) <= 4.5)
    if len(near) == 0:
        return near, np.zeros(0)
    n = grid.nperseg
    x = grid.bins[near] - k0
    W = 0.5 * _dirichlet(x, n) - 0.25 * _dirichlet(x - 1, n) - 0.25 * _dirichlet(x + 1, n)
    return near, 2.0 * (amplitude / 2.0) ** 2 * np.abs(W) ** 2 / (grid.rate_hz * 3.0 * n / 8.0)


class SpectralModel:
    """Expected band spectra of ``channels`` for any configuration of the plant.

    ``quant_psd`` is each channel's quantization floor (V^2/Hz one-sided, from the measured
    file's LSB). Frequency responses are cached by the plant's matrices, so candidates that
    change only noise sources (flicker, jumps, lines) cost no matrix work.
    """

    def __init__(
        self,
        grid: Grid,
        channels: tuple[str, ...],
        mode: int,
        axis: str,
        quant_psd: np.ndarray | None = None,
    ) -> None:
        self.grid, self.channels, self.mode, self.axis = grid, tuple(channels), mode, axis
        self.quant = np.zeros(len(channels)) if quant_psd is None else np.asarray(quant_psd, float)
        self._cache: dict[str, tuple] = {}
        self._source_cache: dict[tuple, list[dict]] = {}
        self._sources_cache: dict[tuple, tuple[dict, list]] = {}
        self._aa_cache: dict[tuple, np.ndarray] = {}
        self._aa_alias_cache: dict[tuple, list[np.ndarray]] = {}
        self._aa_line_cache: dict[tuple, np.ndarray] = {}
        self._kernel_cache: dict[float, tuple[np.ndarray, np.ndarray]] = {}
        self.plant_evaluations = 0

    def _plant(self, cfg: SimConfig, dt: float):
        plant = build_plant(linearized(cfg), relays_for(self.mode))
        missing = [c for c in self.channels if c not in plant.outputs]
        if missing:
            raise ValueError(f"the model has no channel(s) {', '.join(missing)}")
        key = hashlib.sha1(
            b"".join(
                np.ascontiguousarray(m).tobytes() for m in (plant.A, plant.B, plant.C, plant.D)
            )
            + repr(dt).encode()
        ).hexdigest()
        return plant, key

    def _responses(
        self, cfg: SimConfig, m: int, dt: float, inputs: list[str], line_freqs: np.ndarray
    ):
        plant, key = self._plant(cfg, dt)
        key += repr((inputs, line_freqs.tobytes()))
        hit = self._cache.get(key)
        if hit is not None:
            return hit
        self.plant_evaluations += 1
        rows = [plant.outputs.index(c) for c in self.channels]
        cols = [plant.inputs.index(i) for i in inputs]
        fs = self.grid.rate_hz
        f_eval = self.grid.f[self.grid.eval_bins]
        aliases = _aliases(f_eval, fs, m)
        freqs = np.concatenate([np.nan_to_num(a, nan=0.0) for a in aliases] + [line_freqs])
        z = np.exp(2j * np.pi * freqs * dt)
        C, D = plant.C[rows], plant.D[np.ix_(rows, cols)]
        keep = coupled_states(plant.A, plant.B[:, cols], C)
        A_k, B_k = plant.A[np.ix_(keep, keep)], plant.B[np.ix_(keep, cols)]
        # an input that drives none of those states reaches the channels through D alone (the
        # other axes' noise: most of the inputs)
        live = np.flatnonzero(np.any(B_k != 0, axis=0))
        H = np.broadcast_to(D, (len(z), *D.shape)).astype(complex)
        H_live = (
            zoh_response_modal(A_k, B_k[:, live], C[:, keep], D[:, live], dt, z)
            if len(live)
            else H[:, :, live]
        )
        if H_live is None:  # eigenvectors too ill-conditioned: discretize and solve
            disc = discretize(plant, dt)
            H = frequency_response(disc.Ad, disc.Bd[:, cols], C, D, z)
        else:
            H[:, :, live] = H_live
        n = len(f_eval)
        # |H|^2 per alias, (n_in, n_out, n_points): what the noise parts are weighted by
        power = [
            np.ascontiguousarray(np.transpose(np.abs(H[i * n : (i + 1) * n]) ** 2, (2, 1, 0)))
            for i in range(len(aliases))
        ]
        stable = bool(np.max(np.linalg.eigvals(plant.A).real) < 0.0)
        result = (aliases, power, H[len(aliases) * n :], stable)
        if len(self._cache) > 256:
            self._cache.clear()
        self._cache[key] = result
        return result

    def _sources(self, cfg: SimConfig, m: int, dt: float, probe: list[np.ndarray]):
        """Each random input's spectrum at the alias frequencies, by part, and the deterministic
        lines. Each noise source's spectrum is cached on its own parameters."""
        sources = Sources(cfg, 0, dt, spectral=True)
        whole_key = (
            m,
            dt,
            tuple(
                (name, tuple(part.spectrum_key() for part in parts), tuple(sources.lines(name)))
                for name, parts in sources.parts.items()
            ),
        )
        whole = self._sources_cache.get(whole_key)
        if whole is not None:  # a trial that changes only the plant
            return whole
        caches = self._source_cache.setdefault((m, dt), [{} for _ in probe])
        if sum(len(c) for c in caches) > 4096:
            for c in caches:
                c.clear()
        filled = [np.nan_to_num(a, nan=1.0) for a in probe]
        absent = [np.isnan(a) for a in probe]
        spectra: dict[str, dict[str, list[np.ndarray]]] = {}
        for name in sources.names:
            per_alias = [sources.spectrum(name, a, cache) for a, cache in zip(filled, caches)]
            for kind in per_alias[0]:
                s = [np.where(no, 0.0, sp[kind]) for no, sp in zip(absent, per_alias)]
                part = part_of(name, kind, self.axis)
                if part is not None and any(np.any(x > 0) for x in s):
                    acc = spectra.setdefault(name, {}).get(part)
                    spectra[name][part] = s if acc is None else [x + y for x, y in zip(acc, s)]
        fs = self.grid.rate_hz
        lines = [
            (name, f0, a)
            for name in sources.names
            for f0, a in sources.lines(name)
            if 0 < f0 < fs * m / 2
        ]
        if len(self._sources_cache) > 256:
            self._sources_cache.clear()
        self._sources_cache[whole_key] = spectra, lines
        return spectra, lines

    def _aa2(self, cfg: SimConfig, m: int):
        """|AA|^2 of the anti-alias filter, as a function of internal-rate frequency."""
        fs = self.grid.rate_hz
        s = cfg.sampling
        key = (fs, m, s.anti_alias_poles, s.anti_alias_fraction)
        sos = self._aa_cache.get(key)
        if sos is None:
            sos = self._aa_cache[key] = anti_alias_sos(
                s.anti_alias_poles, s.anti_alias_fraction, fs, m
            )

        def aa2(f: np.ndarray) -> np.ndarray:
            return (
                np.abs(
                    scipy.signal.sosfreqz(
                        sos, worN=np.nan_to_num(np.atleast_1d(f), nan=0.0), fs=fs * m
                    )[1]
                )
                ** 2
            )

        return aa2

    def __call__(self, cfg: SimConfig) -> ModelSpectrum:
        grid, fs = self.grid, self.grid.rate_hz
        m, dt = internal_rate(cfg.sampling, fs)
        f_eval = grid.f[grid.eval_bins]
        probe = _aliases(f_eval, fs, m)
        spectra, line_list = self._sources(cfg, m, dt, probe)
        inputs = sorted(set(spectra) | {name for name, _, _ in line_list})
        line_freqs = np.array([f0 for _, f0, _ in line_list], float)
        aliases, power, H_lines, stable = self._responses(cfg, m, dt, inputs, line_freqs)
        aa2 = self._aa2(cfg, m)
        aa_key = (m, dt, cfg.sampling.anti_alias_poles, cfg.sampling.anti_alias_fraction)
        aa_alias = self._aa_alias_cache.get(aa_key)
        if aa_alias is None:
            aa_alias = self._aa_alias_cache[aa_key] = [aa2(a) for a in aliases]

        nch = len(self.channels)
        per_part = {
            p: np.zeros((nch, len(f_eval))) for p in PARTS
        }  # band means taken once, at the end
        for j, name in enumerate(inputs):
            for part, spec in spectra.get(name, {}).items():
                acc = per_part[part]
                for H2, g, sp in zip(power, aa_alias, spec):
                    acc += H2[j] * (g * sp)[None, :]
        parts = {p: grid.eval_mean(v) for p, v in per_part.items()}
        per_bin = np.zeros((nch, len(grid.bins)))
        aa_lines = self._aa_lines(aa2, aa_key, line_freqs)
        own = 0  # the axis gyro's pickoff lines, in the data sheet's order: each a part of its own
        for k, (name, f0, a) in enumerate(line_list):
            amp = a * np.abs(H_lines[k, :, inputs.index(name)]) * aa_lines[k]
            if name == f"np_{self.axis}":
                line_bins = np.zeros_like(per_bin)
                self._add_line(line_bins, f0, amp)
                parts[line_part(own)] = grid.band_mean(line_bins)
                own += 1
            else:
                self._add_line(per_bin, f0, amp)
        for p in cfg.pickup:
            if p.channel in self.channels and 0 < p.freq_hz < fs * m / 2:
                gain = math.sqrt(aa2(p.freq_hz)[0])
                amp = np.zeros(nch)
                amp[self.channels.index(p.channel)] = p.amplitude_V * gain
                self._add_line(per_bin, p.freq_hz, amp)
        parts["fixed"] += grid.band_mean(per_bin) + self.quant[:, None]
        shape = ac_shape(cfg, self.axis) if self.axis in cfg.autocollimator else None
        return ModelSpectrum(self.channels, parts, grid.band_center_hz, shape, stable)

    def _aa_lines(self, aa2, aa_key: tuple, line_freqs: np.ndarray) -> np.ndarray:
        """|AA| at the lines' frequencies (cached: most trials keep the lines)."""
        key = aa_key + (line_freqs.tobytes(),)
        hit = self._aa_line_cache.get(key)
        if hit is None:
            if len(self._aa_line_cache) > 256:
                self._aa_line_cache.clear()
            hit = self._aa_line_cache[key] = (
                np.sqrt(aa2(line_freqs)) if len(line_freqs) else np.zeros(0)
            )
        return hit

    def _add_line(self, per_bin: np.ndarray, f0: float, amplitudes: np.ndarray) -> None:
        fs = self.grid.rate_hz
        fo = f0 % fs
        fo = fs - fo if fo > fs / 2 else fo  # the decimator folds it
        hit = self._kernel_cache.get(fo)
        if hit is None:
            if len(self._kernel_cache) > 1024:
                self._kernel_cache.clear()
            hit = self._kernel_cache[fo] = hann_line_kernel(self.grid, fo, 1.0)
        pos, kern = hit
        if len(pos):
            per_bin[:, pos] += np.asarray(amplitudes)[:, None] ** 2 * kern[None, :]


def lsb(x: np.ndarray) -> float:
    """The recording's quantization step: the smallest step between distinct values, if every
    sample sits on that grid; 0 for data not on a grid (scaled, or simulated in float)."""
    v = np.unique(np.asarray(x[:200_000], float))
    if len(v) < 2:
        return 0.0
    q = float(np.min(np.diff(v)))
    if q <= 0 or not np.allclose(v / q, np.round(v / q), atol=1e-3, rtol=0):
        return 0.0
    return q


def quantization_psd(q: float, rate_hz: float) -> float:
    """One-sided white quantization floor q^2 / (6 fs) of an LSB ``q`` (App. A.7, [Widrow])."""
    return q * q / (6.0 * rate_hz)


def step_response(
    cfg: SimConfig,
    mode: int,
    input_name: str,
    channels: tuple[str, ...],
    rate_hz: float,
    duration_s: float,
    t_step_s: float,
) -> np.ndarray:
    """Response of ``channels`` (n_channels, n) as recorded at ``rate_hz`` (anti-alias filter and
    decimation included) to a unit step of plant input ``input_name`` at ``t_step_s``, from rest."""
    m, dt = internal_rate(cfg.sampling, rate_hz)
    plant = build_plant(cfg, relays_for(mode))
    disc = discretize(plant, dt)
    rows = [plant.outputs.index(c) for c in channels]
    b = disc.Bd[:, plant.inputs.index(input_name)]
    d = plant.D[rows, plant.inputs.index(input_name)]
    C = plant.C[rows]
    n = int(round(duration_s * rate_hz)) * m
    k_step = min(int(round(t_step_s * rate_hz)) * m, n)
    y = np.zeros((n, len(rows)))
    y[k_step:] = _unit_step(disc.Ad, b, C, d, n - k_step)
    sos = anti_alias_sos(
        cfg.sampling.anti_alias_poles, cfg.sampling.anti_alias_fraction, rate_hz, m
    )
    return scipy.signal.sosfilt(sos, y, axis=0)[::m].T


def _unit_step(
    Ad: np.ndarray, b: np.ndarray, C: np.ndarray, d: np.ndarray, n: int, block: int = 256
) -> np.ndarray:
    """y_j = C s_j + d, s_0 = 0, s_(j+1) = Ad s_j + b: the unit-step response (n, n_out) a block
    of ``block`` steps at a time. In a block from state s, s_(j0+i) = Ad^i s + sum_(l<i) Ad^l b,
    so each block is one product with the stacked powers of Ad (no per-sample loop)."""
    ns = len(b)
    powers = np.empty((block + 1, ns, ns))
    powers[0] = np.eye(ns)
    for i in range(1, block + 1):
        powers[i] = Ad @ powers[i - 1]
    sums = np.concatenate(
        [np.zeros((1, ns)), np.cumsum(powers[:-1] @ b, axis=0)]
    )  # sum_(l<i) Ad^l b
    CP, CG = C @ powers[:-1], sums[:-1] @ C.T + d
    y = np.empty((n, len(d)))
    s = np.zeros(ns)
    for j0 in range(0, n, block):
        k = min(block, n - j0)
        y[j0 : j0 + k] = (CP[:k] @ s) + CG[:k]
        s = powers[block] @ s + sums[block]
    return y
