"""Shared by the excitation tests (``test_excitation.py``, ``test_excitation_modes.py``): the
short run's timings, a sim config of a drawn rig, and the check of closed-loop roots against
the linearized model. Two files so that the suite's workers run their sim-rig runs side by side
(``make test`` gives each worker whole files)."""

from __future__ import annotations

import numpy as np

from simhw.plant import linearized_poles

#: shorter than the defaults (which a lab would use), long enough for the tolerances
FAST = {"settle_s": 10.0, "quiet_s": 64.0, "excite_s": 160.0}


def drawn_config(tmp_path, axis, inertia, stiffness, corners):
    text = [
        f"[platform.{axis}]",
        f"inertia_kg_m2 = {inertia}",
        f"[bearing.{axis}]",
        'model = "spring"',
        f"stiffness_Nm_per_rad = {stiffness}",
        "[compensation]",
    ]
    text += [f"{k} = {v}" for k, v in corners.items()]
    path = tmp_path / "drawn.toml"
    path.write_text("\n".join(text) + "\n")
    return path


def assert_roots_near_the_linearized(cl, cfg, mode, axis, tol=0.10):
    """Issue 22 C: each named root within ``tol`` of the nearest root of ``linearized_poles``
    (complex distance over modulus), the platform pair's damping too."""
    lin = linearized_poles(cfg, mode, axis)
    assert set(cl["roots"]) == {"c1", "platform_pair", "c4"}, cl
    for name, r in cl["roots"].items():
        p = complex(*r["pole"])
        q = lin[np.argmin(np.abs(lin - p))]
        print(
            f"Mode {mode} {axis} {name}: {abs(p):.4g} rad/s {r['w_rad_per_s_ci95']}, linearized {abs(q):.4g} "
            f"(zeta {-p.real / abs(p):.3f} / {-q.real / abs(q):.3f})"
        )
        assert abs(p - q) / abs(q) < tol, (name, p, q)
        assert r["resolved"]["w_rad_per_s"], r
    pair = complex(*cl["roots"]["platform_pair"]["pole"])
    q = lin[np.argmin(np.abs(lin - pair))]
    assert abs((-pair.real / abs(pair)) / (-q.real / abs(q)) - 1) < tol
