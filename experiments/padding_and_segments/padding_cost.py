"""What padding with inactive contacts costs (issue 12, part 1): the same 64 grasps
evaluated as one ``jit(vmap(evaluate))`` batch unpadded and padded to more contacts.

For each padding the script prints compile time, steady time per grasp (median of 3
runs), the ratio to the unpadded batch and the largest value difference, all measured
in one run, with the load average. Run: ``python experiments/padding_and_segments/padding_cost.py``.
"""

from __future__ import annotations

import os
import statistics
import time

import jax
import jax.numpy as jnp
import numpy as np

import jaxgrasp

B = 64
PADS = (None, 3, 4, 7)  # None: the grasps' own 2 (cube) or 3 (prism) contacts


def grasps(kind: str) -> list[jaxgrasp.Grasp]:
    e = np.linspace(2e5, 1e6, 8)
    dr = np.linspace(1e-3, 4e-3, 8)
    make = jaxgrasp.presets.cube if kind == "cube" else jaxgrasp.presets.prism
    return [make(young_modulus=float(a), initial_deformation=float(b)) for a in e for b in dr]


def batch(items, pad):
    if pad is None:
        return jax.tree_util.tree_map(lambda *x: jnp.stack(x), *items)
    return jaxgrasp.stack(items, num_contacts=pad)


def measure(items, pad, fn):
    b = batch(items, pad)
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn(b))
    first = time.perf_counter() - t0
    runs = []
    for _ in range(3):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(b))
        runs.append(time.perf_counter() - t0)
    steady = statistics.median(runs)
    return first - steady, steady / len(items), np.asarray(out.value), np.asarray(out.status)


def main():
    print(f"jax {jax.__version__}, {jax.devices()[0].platform}, {os.cpu_count()} CPUs, B = {B}")
    print(f"load average at start: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    for kind in ("cube", "prism"):
        items = grasps(kind)
        base = None
        for pad in PADS:
            n = items[0].num_contacts
            if pad is not None and pad <= n:
                continue
            fn = jax.jit(jax.vmap(jaxgrasp.evaluate))
            compile_s, per, value, status = measure(items, pad, fn)
            if base is None:
                base = (compile_s, per, value, status)
                print(f"{kind}: N={n} unpadded: compile {compile_s:.1f} s, {per * 1e3:.2f} ms/grasp")
                continue
            dv = float(np.max(np.abs(value - base[2]) / np.maximum(np.abs(base[2]), 1e-300)))
            same = bool(np.array_equal(status, base[3]))
            print(
                f"{kind}: padded to N={pad}: compile {compile_s:.1f} s ({compile_s / base[0]:.2f}x), "
                f"{per * 1e3:.2f} ms/grasp ({per / base[1]:.2f}x), max rel value diff {dv:.1e}, "
                f"statuses equal {same}"
            )
    print(f"load average at end: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
