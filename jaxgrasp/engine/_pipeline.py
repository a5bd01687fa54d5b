"""A pipeline of named jitted stages and a driver, and its lowered and compiled forms."""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, Mapping, Sequence

import jax

__all__ = ["Pipeline", "Staged", "lower_stages"]


def _spec_of(x) -> jax.ShapeDtypeStruct:
    """``x``'s shape, dtype and sharding (where it has one)."""
    return jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=getattr(x, "sharding", None))


@dataclasses.dataclass(frozen=True)
class Pipeline:
    """An executable as several jitted stages and the Python function that calls them: what
    ``build`` of `compiled` returns for an executable compiled in stages.

    Attributes:
        stages: stage name -> jitted function (``jax.jit(...)`` with its shardings and
            compiler options; arrays in, a tuple of arrays out).
        drive: ``drive(call, *args)`` -> a tuple of arrays, the whole computation: it runs stage
            ``name`` on arrays ``xs`` by ``call(name, *xs)`` (a tuple of arrays back),
            in any order and as often as it likes, a stage always on arrays of the same
            shapes. It must do nothing else with the arrays but pass them on: it also
            runs on their shapes alone, to compile the stages and to check stored ones.

    Stages compile sooner than the same work as one executable: each stage is
    compiled by XLA in a thread of its own (XLA's compiler releases the GIL) while the
    next is traced and lowered, a stage called twice is compiled once, and each stage
    has its own compiler options (one that runs briefly can be compiled for latency).
    """

    stages: Mapping[str, Callable]
    drive: Callable


class Staged:
    """A compiled `Pipeline`: ``Staged(stages, drive)(*args)`` runs ``drive``
    with each stage's compiled executable (``jax.stages.Compiled``, in `stages`,
    by name, in the order the driver first calls them). Results between stages stay
    on the devices."""

    def __init__(self, stages: Mapping[str, Any], drive: Callable):
        self.stages = dict(stages)
        self.drive = drive

    def __call__(self, *args):
        return self.drive(lambda name, *xs: self.stages[name](*xs), *args)


def lower_stages(pipeline: Pipeline, spec: Sequence, on_lowered: Callable | None = None) -> dict:
    """Run ``pipeline``'s driver on the shapes ``spec`` (``jax.ShapeDtypeStruct``
    leaves, with their shardings), lowering each stage when it is first called; returns
    stage name -> ``jax.stages.Lowered``, in that order. ``on_lowered(name, lowered)``
    is called at once for each (`_compile` starts its XLA compilation there). A
    stage called again on other shapes is a ``ValueError``."""
    lowered: dict[str, tuple] = {}  # name -> (argument specs, jax.stages.Lowered)

    def call(name, *args):
        args = tuple(_spec_of(a) for a in args)
        if name not in lowered:
            lowered[name] = (args, pipeline.stages[name].lower(*args))
            if on_lowered is not None:
                on_lowered(name, lowered[name][1])
        elif lowered[name][0] != args:
            raise ValueError(f"stage {name!r} called on arrays of other shapes: {lowered[name][0]} and {args}")
        return tuple(_spec_of(o) for o in jax.tree_util.tree_leaves(lowered[name][1].out_info))

    pipeline.drive(call, *spec)
    return {name: low for name, (_, low) in lowered.items()}
