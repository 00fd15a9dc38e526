"""The part of the rig a few recorded channels depend on: a structural reduction, exact.

A campaign or the model-gap workflow records four channels of one axis, yet the full model
integrates every state of the rig, filters every channel and draws every noise source. The
outputs asked for depend on a subset only: the states their ``C`` and ``D`` rows read, the
states and inputs those states' derivatives read (``A``, ``B``), and so on until nothing new
is added (backward reachability on the model's sparsity graph). The rest may be dropped
without changing one bit of what is kept:

* the kernel (``simhw.kernel``) sums the nonzeros of each row in column order, and a dropped
  column is a structural zero in every kept row, so each kept sum is the same sum (the held
  inputs' dense product only loses terms that were exact zeros);
* ``e^(A dt)`` and its input integral (``simhw.plant.discretize``) have no nonzero outside the
  reachability of ``A`` and ``B``, so closing over the continuous model closes the discrete
  one too;
* every noise source is its own random stream (``simhw.simulator.Sources``), so drawing fewer
  of them leaves the others as they were;
* the recording chain filters and quantizes each channel on its own.

The nonlinear elements take part as the kernel runs them: one is kept when the input column
its correction writes is kept, or (a mechanical stop, which clamps two states in place) when
its states are; a kept one brings the states and inputs of its pre-signal.

The kept set is the closure over every relay state the simulator can switch to (modes 1-6,
caging loops all closed and all inhibited, wheels stopped and at speed), so the state layout
never changes on a mode switch: a state outside the set never influences one inside it in any
of them. The linear steady-state start (``Simulator._settle``) solves the whole rig and keeps
its part: the kept block alone has the same solution in exact arithmetic, but a smaller LU
rounds differently (1e-13 relative, measured), and the reduced run would no longer be the full
run to the bit. ``tests/simhw/test_reduced_channels.py`` checks the claim, bit for bit.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from simhw.config import MODES, SimConfig
from simhw.plant import NL_STOP, DiscretePlant, Lin, Nonlinearity, Plant, RelayState, build_plant

#: relay states whose union of couplings the kept set is closed over
_SPINS = (0.0, 1.0)
_CAGING = ((False,) * 4, (True,) * 4)


@dataclass(frozen=True)
class Kept:
    """The names a reduced run keeps: outputs (in the caller's order), states, inputs and
    nonlinear elements. Names, not indices: the inputs differ between modes (mode 6 has no
    torquer bias inputs)."""

    outputs: tuple[str, ...]
    states: frozenset[str]
    inputs: frozenset[str]
    nonlinear: frozenset[str]


#: a node of the dependency graph: ("x", state), ("u", input) or ("y", output), by name
Node = tuple[str, str]


@dataclass
class _Element:
    """A nonlinear element as the closure sees it."""

    col: Node | None  # the input its correction is written to
    reads: set[Node] = field(default_factory=set)  # its pre-signal's states and inputs
    clamps: set[Node] = field(default_factory=set)  # states a stop clamps in place


def _graph(plants: Iterable[Plant]) -> tuple[dict[Node, set[Node]], dict[str, _Element]]:
    """The union over ``plants`` of what each state and output reads (the nonzeros of its row of
    A, B or C, D), and of each nonlinear element's column, reads and clamped states."""
    reads: dict[Node, set[Node]] = {}
    elements: dict[str, _Element] = {}
    for p in plants:

        def node(kind: str, i: int, p: Plant = p) -> Node:
            return (kind, p.states[i] if kind == "x" else p.inputs[i])

        for kind, rows, m_x, m_u in (("x", p.states, p.A, p.B), ("y", p.outputs, p.C, p.D)):
            for r, row in enumerate(rows):
                got = reads.setdefault((kind, row), set())
                got.update(node("x", int(i)) for i in np.nonzero(m_x[r])[0])
                got.update(node("u", int(i)) for i in np.nonzero(m_u[r])[0])
        for n in p.nonlinear:
            e = elements.setdefault(n.name, _Element(node("u", n.col) if n.col >= 0 else None))
            e.reads.update(node(kind, i) for kind, i in n.z)
            if n.kind == NL_STOP:
                e.clamps.update((node("x", n.state_theta), node("x", n.state_omega)))
    return reads, elements


def relay_states() -> list[RelayState]:
    """The relay states the closure covers: any wheel speed between 0 and 1 has the couplings of
    1 (the speed scales them), any mix of caging inhibits the union of all-on and all-off."""
    return [RelayState(m, cage, s) for m in MODES for cage in _CAGING for s in _SPINS]


def kept(cfg: SimConfig, outputs: Sequence[str]) -> Kept:
    """The states, inputs and nonlinear elements the model's ``outputs`` depend on, in any relay
    state (the closure of the module docstring)."""
    plants = [build_plant(cfg, r) for r in relay_states()]
    unknown = [o for o in outputs if o not in plants[0].outputs]
    if unknown:
        raise ValueError(
            f"no model output {', '.join(map(repr, unknown))} "
            f"(the outputs are {', '.join(plants[0].outputs)})"
        )
    if any(p.states != plants[0].states for p in plants):
        raise RuntimeError(
            "the model's states differ between relay states: a reduced run would be wrong"
        )
    reads, elements = _graph(plants)
    need: set[Node] = set()
    chosen: set[str] = set()
    todo: list[Node] = [("y", o) for o in outputs]
    while todo:
        for dep in reads.get(todo.pop(), ()):
            if dep not in need:
                need.add(dep)
                todo.append(dep)
        if not todo:
            for name, e in elements.items():
                if name not in chosen and (
                    (e.col is not None and e.col in need) or e.clamps & need
                ):
                    chosen.add(name)
                    more = e.reads | e.clamps | ({e.col} if e.col is not None else set())
                    todo += [d for d in more if d not in need]
                    need |= more
    return Kept(
        tuple(outputs),
        frozenset(n for k, n in need if k == "x"),
        frozenset(n for k, n in need if k == "u"),
        frozenset(chosen),
    )


def reduce(disc: DiscretePlant, keep: Kept) -> DiscretePlant:
    """``disc`` restricted to ``keep``: matrices sliced (each kept name in the model's order),
    the nonlinear elements' state and input indices renumbered, the slow inputs those kept."""
    p = disc.plant
    xs = [i for i, n in enumerate(p.states) if n in keep.states]
    us = [i for i, n in enumerate(p.inputs) if n in keep.inputs]
    ys = [p.outputs.index(o) for o in keep.outputs]
    x_new = {old: new for new, old in enumerate(xs)}
    u_new = {old: new for new, old in enumerate(us)}

    def renumber(n: Nonlinearity) -> Nonlinearity:
        z = {(kind, x_new[i] if kind == "x" else u_new[i]): v for (kind, i), v in n.z.items()}
        return dataclasses.replace(
            n,
            z=Lin(z),
            col=u_new[n.col] if n.col >= 0 else -1,
            state_theta=x_new[n.state_theta] if n.state_theta >= 0 else -1,
            state_omega=x_new[n.state_omega] if n.state_omega >= 0 else -1,
        )

    inputs = [p.inputs[i] for i in us]
    plant = Plant(
        states=[p.states[i] for i in xs],
        inputs=inputs,
        outputs=list(keep.outputs),
        A=p.A[np.ix_(xs, xs)],
        B=p.B[np.ix_(xs, us)],
        C=p.C[np.ix_(ys, xs)],
        D=p.D[np.ix_(ys, us)],
        nonlinear=[renumber(n) for n in p.nonlinear if n.name in keep.nonlinear],
        slow_inputs=[s for s in p.slow_inputs if s in inputs],
    )
    return DiscretePlant(plant, disc.dt, disc.Ad[np.ix_(xs, xs)], disc.Bd[np.ix_(xs, us)])
