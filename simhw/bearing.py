"""Gimbal bearing torque models (Ch. III G, Ch. V F).

Each model splits into a linear part that goes into the plant's state-space matrix (so it is
integrated exactly) and, for Dahl's model, a nonlinear residual that the kernel computes each
step and holds over it. The split keeps the held part tiny for small motion, where Dahl's
model is a spring of stiffness eta To^2.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba

from simhw.config import Bearing


@dataclass(frozen=True)
class BearingLinearPart:
    stiffness_Nm_per_rad: float
    damping_Nms: float
    dahl: bool  # True: the kernel adds the Dahl residual -T + k theta


def linear_part(b: Bearing) -> BearingLinearPart:
    """Linear stiffness and damping of a bearing model, and whether a Dahl residual follows."""
    if b.model == "none":
        return BearingLinearPart(0.0, 0.0, False)
    if b.model == "viscous":
        return BearingLinearPart(0.0, b.damping_Nms, False)
    if b.model == "spring":
        return BearingLinearPart(b.stiffness_Nm_per_rad, 0.0, False)
    if b.model == "dahl":
        return BearingLinearPart(dahl_stiffness(b.To_Nm, b.eta_per_Nm), 0.0, True)
    raise ValueError(f"unknown bearing model {b.model!r}")


def dahl_stiffness(To_Nm: float, eta_per_Nm: float) -> float:
    """Small-motion stiffness of Dahl's model, eta To^2 (Ch. V F.4, after eq. 5.3)."""
    return eta_per_Nm * To_Nm * To_Nm


@numba.njit(cache=True, nogil=True)
def dahl_step(T: float, dtheta: float, To: float, eta: float) -> float:
    """Exact update of Dahl's friction torque over a monotone angle increment (eq. 5.2-5.3).

    dT/dtheta = eta (T - To)^2 for dtheta > 0 integrates to 1/(To - T) += eta dtheta;
    dT/dtheta = eta (T + To)^2 for dtheta < 0 integrates to 1/(T + To) -= eta dtheta.
    The friction torque T opposes motion; the torque on the platform is -T.
    """
    # At the Coulomb limit (T = +-To, reached in floating point by a large step) the
    # reciprocal is infinite and T stays at the limit.
    if dtheta > 0.0:
        return To if T >= To else To - 1.0 / (1.0 / (To - T) + eta * dtheta)
    if dtheta < 0.0:
        return -To if T <= -To else 1.0 / (1.0 / (T + To) - eta * dtheta) - To
    return T
