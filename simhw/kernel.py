"""The per-step loop of the simulated rig, compiled with numba.

One step: evaluate the nonlinearities from the state at the step's start (writing their
corrections into the input row), produce the outputs y = C x + D u, advance
x <- Ad x + Bd u. Matrices arrive in compressed form because the rig's model is block sparse
(axes decouple in mode 3, the gyros only listen to the platform): about a third of the dense
work. DESIGN.md section 9: a Python loop manages ~1e6 steps/s, numba ~6e7 simple steps/s.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numba
import numpy as np

from simhw.bearing import dahl_step
from simhw.plant import NL_CLIP, NL_DAHL, NL_SOFTSAT, NL_STOP, DiscretePlant


@dataclass
class Csr:
    ptr: np.ndarray
    idx: np.ndarray
    val: np.ndarray

    @classmethod
    def from_dense(cls, M: np.ndarray) -> Csr:
        ptr = [0]
        idx: list[int] = []
        val: list[float] = []
        for row in M:
            nz = np.nonzero(row)[0]
            idx.extend(nz)
            val.extend(row[nz])
            ptr.append(len(idx))
        return cls(
            np.asarray(ptr, np.int64), np.asarray(idx, np.int64), np.asarray(val, np.float64)
        )


@dataclass
class CompiledPlant:
    """A :class:`DiscretePlant` packed for the kernel; fast inputs are given per step."""

    disc: DiscretePlant
    fast_cols: np.ndarray  # input indices that vary per step, in kernel column order
    slow_cols: np.ndarray  # input indices held over a whole block
    ad: Csr
    bf_t: Csr  # Bd[:, fast] transposed: one row per fast input (skipped when 0)
    bs: np.ndarray  # Bd[:, slow]
    c: Csr
    df_t: Csr
    ds: np.ndarray
    nl_kind: np.ndarray
    nl_zx: Csr
    nl_zu: Csr  # over fast columns
    nl_zs: np.ndarray  # over slow columns (dense, tiny)
    nl_col: np.ndarray  # fast column receiving the correction, -1 for none
    nl_p: np.ndarray  # (n_nl, 3): p1, p2, gain
    nl_sidx: np.ndarray  # (n_nl, 2): theta, omega state indices for stops

    @classmethod
    def build(cls, disc: DiscretePlant) -> CompiledPlant:
        plant = disc.plant
        slow = np.array([plant.inputs.index(s) for s in plant.slow_inputs], np.int64)
        fast = np.array([i for i in range(len(plant.inputs)) if i not in set(slow)], np.int64)
        pos = {int(i): k for k, i in enumerate(fast)}
        nl = plant.nonlinear
        zx = np.zeros((len(nl), len(plant.states)))
        zu = np.zeros((len(nl), len(fast)))
        zs = np.zeros((len(nl), len(slow)))
        slow_pos = {int(i): k for k, i in enumerate(slow)}
        for j, n in enumerate(nl):
            for (kind, i), v in n.z.items():
                if kind == "x":
                    zx[j, i] += v
                elif i in pos:
                    zu[j, pos[i]] += v
                else:
                    zs[j, slow_pos[i]] += v
        return cls(
            disc,
            fast,
            slow,
            Csr.from_dense(disc.Ad),
            Csr.from_dense(disc.Bd[:, fast].T),
            disc.Bd[:, slow].copy(),
            Csr.from_dense(plant.C),
            Csr.from_dense(plant.D[:, fast].T),
            plant.D[:, slow].copy(),
            np.array([n.kind for n in nl], np.int64),
            Csr.from_dense(zx),
            Csr.from_dense(zu),
            zs,
            np.array([pos[n.col] if n.col >= 0 else -1 for n in nl], np.int64),
            np.array([[n.p1, n.p2, n.gain] for n in nl], np.float64).reshape(len(nl), 3),
            np.array([[n.state_theta, n.state_omega] for n in nl], np.int64).reshape(len(nl), 2),
        )

    def run(
        self,
        x: np.ndarray,
        u_fast: np.ndarray,
        u_slow: np.ndarray,
        nl_state: np.ndarray,
        y: np.ndarray,
    ) -> None:
        """Advance ``x`` over ``len(u_fast)`` steps, writing outputs to ``y`` (in place)."""
        self.run_pieces(x, u_fast, [(len(u_fast), u_slow)], nl_state, y)

    def run_pieces(
        self,
        x: np.ndarray,
        u_fast: np.ndarray,
        pieces: Sequence[tuple[int, np.ndarray]],
        nl_state: np.ndarray,
        y: np.ndarray,
    ) -> np.ndarray:
        """``run`` over consecutive pieces of ``u_fast``, each (steps > 0, its slow inputs): a
        stream's set-points stepping inside one call rather than a call each, the same
        arithmetic step for step (each piece's slow terms are the products ``run`` forms).
        Returns the pieces' slow inputs stacked, one row a piece (the caller's staircase
        correction reads them: built once a block)."""
        slows = np.array([u_slow for _, u_slow in pieces], np.float64).reshape(
            len(pieces), self.bs.shape[1]
        )
        ends = np.cumsum(np.array([m for m, _ in pieces], np.int64))
        end = int(ends[-1]) if len(ends) else 0
        if end != len(u_fast):
            raise ValueError(f"pieces of {end} steps for {len(u_fast)} noise rows")
        b_slow = matvec_rows(self.bs, slows)
        y_slow = matvec_rows(self.ds, slows)
        z_slow = matvec_rows(self.nl_zs, slows)
        _run(
            x,
            u_fast,
            ends,
            b_slow,
            y_slow,
            z_slow,
            self.ad.ptr,
            self.ad.idx,
            self.ad.val,
            self.bf_t.ptr,
            self.bf_t.idx,
            self.bf_t.val,
            self.c.ptr,
            self.c.idx,
            self.c.val,
            self.df_t.ptr,
            self.df_t.idx,
            self.df_t.val,
            self.nl_kind,
            self.nl_zx.ptr,
            self.nl_zx.idx,
            self.nl_zx.val,
            self.nl_zu.ptr,
            self.nl_zu.idx,
            self.nl_zu.val,
            self.nl_col,
            self.nl_p,
            self.nl_sidx,
            nl_state,
            y,
        )
        return slows


@numba.njit(cache=True, nogil=True)
def matvec_rows(M: np.ndarray, U: np.ndarray) -> np.ndarray:
    """``M @ U[k]`` for every row k of ``U``, each summed in column order: one compiled call
    for a stream's pieces rather than three BLAS calls a piece, and the same sums however many
    pieces there are (a split run and a stepped one agree to the bit)."""
    out = np.empty((U.shape[0], M.shape[0]))
    for k in range(U.shape[0]):
        for i in range(M.shape[0]):
            acc = 0.0
            for j in range(M.shape[1]):
                acc += M[i, j] * U[k, j]
            out[k, i] = acc
    return out


@numba.njit(cache=True, nogil=True)
def half_steps(
    ds: np.ndarray, slows: np.ndarray, before: np.ndarray, rows: np.ndarray, y: np.ndarray
) -> None:
    """Take half of each slow input's step out of the output row where it steps: piece k's
    slow inputs ``slows[k]`` start at row ``rows[k]`` of ``y`` after ``slows[k - 1]``
    (``before`` for the first), and ``y[rows[k]] -= ds @ (step / 2)`` where they changed."""
    prev = before
    for k in range(slows.shape[0]):
        changed = False
        for j in range(slows.shape[1]):
            if slows[k, j] != prev[j]:
                changed = True
                break
        if changed:
            r = rows[k]
            for i in range(ds.shape[0]):
                acc = 0.0
                for j in range(ds.shape[1]):
                    acc += ds[i, j] * (0.5 * (slows[k, j] - prev[j]))
                y[r, i] -= acc
        prev = slows[k]


@numba.njit(cache=True, nogil=True)
def _softsat(z: float, lim: float, ceil: float) -> float:
    a = abs(z)
    if a <= lim:
        return z
    out = lim + (ceil - lim) * np.tanh((a - lim) / (ceil - lim))
    return out if z > 0 else -out


@numba.njit(cache=True, nogil=True)
def _run(
    x,
    u,
    ends,
    b_slows,
    y_slows,
    z_slows,
    ad_ptr,
    ad_idx,
    ad_val,
    bf_ptr,
    bf_idx,
    bf_val,
    c_ptr,
    c_idx,
    c_val,
    df_ptr,
    df_idx,
    df_val,
    nl_kind,
    zx_ptr,
    zx_idx,
    zx_val,
    zu_ptr,
    zu_idx,
    zu_val,
    nl_col,
    nl_p,
    nl_sidx,
    nl_state,
    y,
):
    nx = x.shape[0]
    ny = y.shape[1]
    nf = u.shape[1]
    xn = np.empty(nx)
    piece = 0
    b_slow, y_slow, z_slow = b_slows[0], y_slows[0], z_slows[0]
    for k in range(u.shape[0]):
        if k == ends[piece]:  # the next piece's slow inputs (a set-point stepped here)
            piece += 1
            b_slow, y_slow, z_slow = b_slows[piece], y_slows[piece], z_slows[piece]
        uk = u[k]
        # Nonlinear corrections, in build order (later pre-signals may use earlier ones).
        for j in range(nl_kind.shape[0]):
            z = z_slow[j]
            for q in range(zx_ptr[j], zx_ptr[j + 1]):
                z += zx_val[q] * x[zx_idx[q]]
            for q in range(zu_ptr[j], zu_ptr[j + 1]):
                z += zu_val[q] * uk[zu_idx[q]]
            kind = nl_kind[j]
            p1 = nl_p[j, 0]
            if kind == NL_CLIP:
                out = min(max(z, -p1), p1)
                uk[nl_col[j]] = out - z
            elif kind == NL_SOFTSAT:
                uk[nl_col[j]] = _softsat(z, p1, nl_p[j, 1]) - z
            elif kind == NL_DAHL:  # eq. 5.2, integrated exactly along the step's angle change
                T = nl_state[j, 0]
                prev = nl_state[j, 1]
                if np.isnan(prev):
                    prev = z
                T = dahl_step(T, z - prev, p1, nl_p[j, 1])
                nl_state[j, 0] = T
                nl_state[j, 1] = z
                uk[nl_col[j]] = -T - nl_p[j, 2] * z
            elif kind == NL_STOP:  # inelastic mechanical stop
                it = nl_sidx[j, 0]
                iw = nl_sidx[j, 1]
                if x[it] > p1:
                    x[it] = p1
                    if x[iw] > 0.0:
                        x[iw] = 0.0
                elif x[it] < -p1:
                    x[it] = -p1
                    if x[iw] < 0.0:
                        x[iw] = 0.0
        # Outputs.
        for i in range(ny):
            acc = y_slow[i]
            for q in range(c_ptr[i], c_ptr[i + 1]):
                acc += c_val[q] * x[c_idx[q]]
            y[k, i] = acc
        for f in range(nf):
            v = uk[f]
            if v != 0.0:
                for q in range(df_ptr[f], df_ptr[f + 1]):
                    y[k, df_idx[q]] += df_val[q] * v
        # State update.
        for i in range(nx):
            acc = b_slow[i]
            for q in range(ad_ptr[i], ad_ptr[i + 1]):
                acc += ad_val[q] * x[ad_idx[q]]
            xn[i] = acc
        for f in range(nf):
            v = uk[f]
            if v != 0.0:
                for q in range(bf_ptr[f], bf_ptr[f + 1]):
                    xn[bf_idx[q]] += bf_val[q] * v
        for i in range(nx):
            x[i] = xn[i]
