"""Figures for procedure reports: matplotlib's object API and the Agg canvas only (no pyplot
global state, no GUI backend), like ``daq.plots``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

DPI = 110


def new_figure(nrows: int = 1, ncols: int = 1, figsize: tuple[float, float] = (9.0, 5.5)) -> tuple[Figure, np.ndarray]:
    """A figure with an (nrows, ncols) array of axes."""
    fig = Figure(figsize=figsize)
    FigureCanvasAgg(fig)
    axes = np.atleast_1d(fig.subplots(nrows, ncols, squeeze=False))
    return fig, axes


def save_figure(fig: Figure, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI, format="png")
    fig.clear()
    return path
