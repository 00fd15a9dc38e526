"""Noise sources of the simulated rig, generated block by block and deterministic per seed.

Every source owns its own random stream (spawned from one ``SeedSequence``) and consumes it
strictly sequentially, so the samples do not depend on how a run is cut into blocks.

Flicker (1/f) noise follows the thesis's reference [T1] (Ch. V B.5): a sum of first-order
lags driven by independent white noises, with time constants spread evenly in log frequency.
With lags at corner frequencies f_i spaced by d = ln(f_{i+1}/f_i) and white intensities
q_i = 4 pi d A f_i (two-sided), the sum has one-sided PSD A/f between the extreme corners
(integrate q(fc)/(4 pi^2 (fc^2 + f^2)) over ln fc). Slow lags run at a decimated rate and are
held, so a bank spanning 1e-5..50 Hz costs little per sample.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import scipy.signal


def held_psd(s_norm: np.ndarray, dt: float) -> np.ndarray:
    """One-sided PSD (units^2/Hz) of a sequence held over steps ``dt`` from its per-sample
    two-sided spectrum ``s_norm`` = sum_k R[k] e^(-j w k): the plant's exact ZOH model sees the
    held sequence, so its output PSD is |H(e^(j w))|^2 times this. White of variance s^2 gives
    2 s^2 dt, the ``psd`` it was made from."""
    return 2.0 * dt * np.asarray(s_norm)


def _ar1_norm(a: np.ndarray | float, var_in: np.ndarray | float, w: np.ndarray) -> np.ndarray:
    """Per-sample spectrum of x[n] = a x[n-1] + e[n], var(e) = var_in: var_in / |1 - a e^(-jw)|^2."""
    return var_in / np.abs(1.0 - a * np.exp(-1j * w)) ** 2


class WhiteNoise:
    """Band-limited white noise held over each step: one-sided PSD ``psd`` up to Nyquist."""

    def __init__(self, rng: np.random.Generator, psd: float, dt: float) -> None:
        self.rng = rng
        self.sigma = math.sqrt(psd / (2.0 * dt)) if psd > 0 else 0.0

    def take(self, n: int) -> np.ndarray:
        if self.sigma == 0.0:
            return np.zeros(n)
        return self.sigma * self.rng.standard_normal(n)

    def spectrum_key(self) -> tuple:
        """Everything the spectrum depends on (model-gap caches spectra by it)."""
        return ("WhiteNoise", self.sigma)

    def spectrum(self, f: np.ndarray, dt: float) -> np.ndarray:
        """One-sided PSD of the held sequence, 2 dt S(w) (see :func:`held_psd`)."""
        return held_psd(np.full(np.shape(f), self.sigma**2), dt)


@numba.njit(cache=True, nogil=True)
def _gm_bank(state, a, b, xi, out_sum):
    n, m = xi.shape
    for k in range(n):
        acc = 0.0
        for j in range(m):
            state[j] = a[j] * state[j] + b[j] * xi[k, j]
            acc += state[j]
        out_sum[k] = acc


class FlickerNoise:
    """One-sided PSD ``level / f`` between ``f_lo`` and ``f_hi`` (units^2/Hz at 1 Hz = level)."""

    PER_DECADE = 2.5

    def __init__(self, rng: np.random.Generator, level: float, f_lo: float, f_hi: float, dt: float) -> None:
        self.level, self.f_lo, self.f_hi, self.dt = level, f_lo, f_hi, dt
        self.rng = rng
        self._groups: list[dict] | None = None
        self.ahead = np.zeros(0)

    def _bank(self) -> list[tuple[int, np.ndarray, np.ndarray, np.ndarray]]:
        """The lags, deterministic: (decimation, a, b, stationary variance) per group."""
        if self.level <= 0:
            return []
        dt = self.dt
        f_hi = min(self.f_hi, 0.2 / dt)
        n = max(2, int(math.ceil(math.log10(f_hi / self.f_lo) * self.PER_DECADE)) + 1)
        fc = np.geomspace(self.f_lo, f_hi, n)
        d = math.log(fc[1] / fc[0])
        q = 4 * math.pi * d * self.level * fc
        # Group lags by decimation (power of two) so each runs at >= 40 x its corner.
        decim = np.maximum(1, 2 ** np.floor(np.log2(1.0 / (40.0 * fc * dt)))).astype(np.int64)
        out = []
        for dec in sorted(set(decim.tolist())):
            sel = decim == dec
            w = 2 * math.pi * fc[sel]
            a = np.exp(-w * dt * dec)
            var = q[sel] / (2 * w)  # stationary variance of each lag
            out.append((int(dec), a, np.sqrt(var * (1 - a * a)), var))
        return out

    @property
    def groups(self) -> list[dict]:
        """The running lags, made on first use (the random draws happen then, in a fixed order)."""
        if self._groups is None:
            self._groups = []
            for dec, a, b, var in self._bank():
                x0 = np.sqrt(var) * self.rng.standard_normal(len(a))  # start in steady state
                self._groups.append({"dec": dec, "a": a, "b": b, "state": x0,
                                     "rng": np.random.Generator(np.random.PCG64(self.rng.integers(2**63))),
                                     "held": np.zeros(0), "pos": 0})
        return self._groups

    def spectrum_key(self) -> tuple:
        return ("FlickerNoise", self.level, self.f_lo, self.f_hi, self.dt)

    def initial(self) -> float:
        """The bank's value at the start (its lags' steady-state draws)."""
        return float(sum(g["state"].sum() for g in self.groups))

    def spectrum(self, f: np.ndarray, dt: float) -> np.ndarray:
        """One-sided PSD of the bank as the plant sees it: each group is a set of AR(1) lags at
        step ``dec dt``, held for ``dec`` steps; a held sequence has per-sample spectrum
        |P(w)|^2 S_x(dec w) / dec with P the ``dec``-step box (zero-order-hold upsampling)."""
        f = np.asarray(f, float)
        w = 2 * np.pi * f * dt
        total = np.zeros_like(f)
        for dec, a_all, b_all, _ in self._bank():
            sx = sum(_ar1_norm(a, b * b, dec * w) for a, b in zip(a_all, b_all))
            if dec > 1:
                with np.errstate(invalid="ignore", divide="ignore"):
                    box = np.where(np.abs(np.sin(w / 2)) < 1e-300, float(dec * dec),
                                   (np.sin(dec * w / 2) / np.sin(w / 2)) ** 2)
                sx = sx * box / dec
            total += sx
        return held_psd(total, dt)

    #: Samples are made ahead in chunks of this many steps, always on the same grid from the
    #: run's start, so the output does not depend on how callers cut the run into blocks.
    CHUNK = 4096

    def take(self, n: int) -> np.ndarray:
        if not self.groups:
            return np.zeros(n)
        while len(self.ahead) < n:
            self.ahead = np.concatenate([self.ahead, self._generate(self.CHUNK)])
        out, self.ahead = self.ahead[:n], self.ahead[n:]
        return out

    def _generate(self, n: int) -> np.ndarray:
        out = np.zeros(n)
        for g in self.groups:
            # ``held`` are slow samples not yet fully used; ``pos`` fine steps of held[0] used.
            dec, pos = g["dec"], g["pos"]
            need = -(-(pos + n) // dec) - len(g["held"])
            if need > 0:
                xi = g["rng"].standard_normal((need, len(g["a"])))
                s = np.empty(need)
                _gm_bank(g["state"], g["a"], g["b"], xi, s)
                g["held"] = np.concatenate([g["held"], s])
            if dec == 1:
                out += g["held"][:n]
            else:
                out += g["held"][(pos + np.arange(n)) // dec]
            used, g["pos"] = divmod(pos + n, dec)
            g["held"] = g["held"][used:]
        return out


class ExcessFlickerNoise(FlickerNoise):
    """1/f noise beyond a sensor's own (air turbulence in the optical path: the
    ``flicker_noise`` effect, Ch. V B.3). The same process as ``FlickerNoise``, kept a kind of
    its own so an analysis can tell the unit's own 1/f (unit-to-unit variation) from the excess
    (physics the nominal model lacks)."""


class RandomWalk:
    """Integrated white noise: increments of std ``k sqrt(dt)`` (rate random walk)."""

    def __init__(self, rng: np.random.Generator, k: float, dt: float) -> None:
        self.rng, self.step, self.value = rng, k * math.sqrt(dt), 0.0

    def take(self, n: int) -> np.ndarray:
        if self.step == 0.0 or n == 0:
            return np.zeros(n)
        # The carried value starts the sum, so any cut of the run gives the same samples.
        w = np.cumsum(np.concatenate([[self.value], self.step * self.rng.standard_normal(n)]))[1:]
        self.value = float(w[-1])
        return w

    def spectrum_key(self) -> tuple:
        return ("RandomWalk", self.step)

    def spectrum(self, f: np.ndarray, dt: float) -> np.ndarray:
        """step^2 / |1 - e^(-jw)|^2: the random walk's (improper) spectrum, infinite at f = 0."""
        w = 2 * np.pi * np.asarray(f, float) * dt
        with np.errstate(divide="ignore"):
            return held_psd(_ar1_norm(1.0, self.step**2, w), dt)


#: The line rotation restarts from the exact phase every this many steps, counted from the
#: run's start, so rounding never accumulates and no cut of the run changes a sample.
_LINE_RESEED = 4096


@numba.njit(cache=True, nogil=True)
def _lines(k0, freq_dt, amp, phase, out):
    """Sum of amp sin(2 pi f dt k + phase) for k = k0..k0+n-1, by complex rotation."""
    n = out.shape[0]
    for j in range(freq_dt.shape[0]):
        w = 2.0 * np.pi * freq_dt[j]
        cw, sw = np.cos(w), np.sin(w)
        # Resume as if rotating since the last restart point: exact whatever the block cuts.
        kb = (k0 // _LINE_RESEED) * _LINE_RESEED
        start = 2.0 * np.pi * ((kb * freq_dt[j]) % 1.0) + phase[j]
        c, s = np.cos(start), np.sin(start)
        for _ in range(k0 - kb):
            c, s = c * cw - s * sw, s * cw + c * sw
        for k in range(n):
            kk = k0 + k
            if kk % _LINE_RESEED == 0:
                start = 2.0 * np.pi * ((kk * freq_dt[j]) % 1.0) + phase[j]
                c, s = np.cos(start), np.sin(start)
            out[k] += amp[j] * s
            c, s = c * cw - s * sw, s * cw + c * sw


class Lines:
    """Sinusoids of fixed amplitude, phase-continuous across blocks; random phases from
    ``rng``, or all starting at ``phase`` (rad) when it is given."""

    def __init__(self, rng: np.random.Generator | None, lines: list[tuple[float, float]], dt: float,
                 phase: float | None = None) -> None:
        self.freq_dt = np.array([f * dt for f, _ in lines], float)
        self.amp = np.array([a for _, a in lines], float)
        if phase is not None:
            self.phase = np.full(len(lines), phase)
        elif rng is not None:
            self.phase = rng.uniform(0, 2 * math.pi, len(lines))
        else:
            raise ValueError("random line phases need an rng; pass one, or a fixed phase")
        self.k = 0

    def take(self, n: int) -> np.ndarray:
        out = np.zeros(n)
        _lines(self.k, self.freq_dt, self.amp, self.phase, out)
        self.k += n
        return out

    def spectrum_key(self) -> tuple:
        return ("Lines",)

    def spectrum(self, f: np.ndarray, dt: float) -> np.ndarray:
        """Deterministic: no continuous spectrum (the sinusoids are given by :meth:`lines`)."""
        return np.zeros(np.shape(f))

    def lines(self, dt: float) -> list[tuple[float, float]]:
        """The sinusoids as (frequency Hz, amplitude)."""
        return [(fd / dt, a) for fd, a in zip(self.freq_dt, self.amp)]


class LagNoise:
    """White noise through w/(s+w), w = 2 pi corner (exact ZOH), scaled to ``rms``.

    The lag passes int_0^inf S/(1 + (f/fc)^2) df = S fc pi/2, so S = 2 rms^2/(pi fc).
    """

    def __init__(self, rng: np.random.Generator, rms: float, corner_hz: float, dt: float) -> None:
        self.white = WhiteNoise(rng, 2 * rms * rms / (math.pi * corner_hz), dt)
        self.a = math.exp(-2 * math.pi * corner_hz * dt)
        self.y = 0.0

    def take(self, n: int) -> np.ndarray:
        if self.white.sigma == 0.0:
            return np.zeros(n)
        y, _ = scipy.signal.lfilter([1 - self.a], [1, -self.a], self.white.take(n), zi=[self.a * self.y])
        self.y = float(y[-1])
        return y

    def spectrum_key(self) -> tuple:
        return ("LagNoise", self.a, self.white.sigma)

    def initial(self) -> float:
        return self.y

    def spectrum(self, f: np.ndarray, dt: float) -> np.ndarray:
        w = 2 * np.pi * np.asarray(f, float) * dt
        return held_psd(_ar1_norm(self.a, ((1 - self.a) * self.white.sigma) ** 2, w), dt)


class TelegraphJumps:
    """Random offset steps of +-amplitude at Poisson times (the thesis's locked-oscillator
    offsets: square-wave-like jumps of tens of urad, 40-400 s apart, Ch. II B.10)."""

    def __init__(self, rng: np.random.Generator, amplitude: float, mean_interval_s: float, dt: float) -> None:
        self.rng, self.amp, self.p = rng, amplitude, dt / mean_interval_s
        self.level = amplitude * (1 if rng.random() < 0.5 else -1)

    def take(self, n: int) -> np.ndarray:
        if self.amp == 0.0 or n == 0:
            return np.zeros(n)
        flips = self.rng.random(n) < self.p
        sign = np.where(np.cumsum(flips) % 2 == 1, -1.0, 1.0)
        out = self.level * sign
        self.level = float(out[-1])
        return out

    def spectrum_key(self) -> tuple:
        return ("TelegraphJumps", self.amp, self.p)

    def initial(self) -> float:
        return self.level if self.amp else 0.0

    def spectrum(self, f: np.ndarray, dt: float) -> np.ndarray:
        """A random telegraph signal flipping with probability p per step has autocorrelation
        A^2 (1 - 2p)^|k|: an AR(1) spectrum with r = 1 - 2p and innovation variance A^2 (1 - r^2)."""
        w = 2 * np.pi * np.asarray(f, float) * dt
        r = 1.0 - 2.0 * self.p
        return held_psd(_ar1_norm(r, self.amp**2 * (1 - r * r), w), dt)
