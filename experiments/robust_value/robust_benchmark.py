"""What the robust value costs (issue 39's done-when): 256 samples of one 3-contact grasp
(:func:`jaxgrasp.robust`, the nominal included) against 256 distinct 3-contact grasps
through :func:`jaxgrasp.evaluate_batch`, in one run, both warm (each run once before it is
timed, so that neither pays a compilation), ``REPEATS`` interleaved runs; the ratios of the
fastest runs (the least disturbed on a shared machine) and of the medians, and the load
average at the start and the end.

The grasp is the paper's prism (3 contacts) with a 0.1 kg mass and the issue's
uncertainty ``friction=0.1,young_modulus=0.1,initial_deformation=2e-4,position=1e-3``.
Three sets of 256 distinct 3-contact grasps, each one ``evaluate_batch`` call:

* ``random``: seeded random grasps (``tests/grasp_draws.py:build_grasp``, seed 1, three
  fingertips), stable or not as drawn;
* ``prisms``: prisms on a grid of 16 Young's moduli (2e5 to 1e6 Pa) x 16 initial
  deformations (1 mm to 0.9 of the force limit's ``sqrt(f_max / (pi E))``), 0.1 kg, all
  stable and symmetric (the easiest kind);
* ``copies``: the robust run's own 256 perturbed copies, as a list (the same work without
  the sampling, the nominal and the statistics).

The nominal's own :func:`jaxgrasp.evaluate` is timed too. Run: ``python experiments/robust_value/robust_benchmark.py`` (log:
``experiments/robust_value/robust_benchmark.log``).
"""

from __future__ import annotations

import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT  # noqa: E402

import jax  # noqa: E402

import jaxgrasp  # noqa: E402
from _lab.grasp_draws import NumpyDraw, build_grasp  # noqa: E402

SAMPLES = 256
REPEATS = 5
SPEC = "friction=0.1,young_modulus=0.1,initial_deformation=2e-4,position=1e-3"


def prisms() -> list[jaxgrasp.Grasp]:
    out = []
    for e in np.linspace(2e5, 1e6, 16):
        top = 0.9 * np.sqrt(15.0 / (np.pi * e))
        out += [jaxgrasp.presets.prism(young_modulus=float(e), initial_deformation=float(dr), mass=0.1)
                for dr in np.linspace(1e-3, top, 16)]
    return out


def random_grasps() -> list[jaxgrasp.Grasp]:
    rng = np.random.default_rng(1)
    return [build_grasp(NumpyDraw(rng), n=3) for _ in range(SAMPLES)]


def copies(grasp, u) -> list[jaxgrasp.Grasp]:
    """The robust run's perturbed copies (:func:`jaxgrasp.analysis.perturbed`), as grasps."""
    out = jaxgrasp.analysis.perturbed(grasp, u, SAMPLES, seed=0).to_numpy_batch()
    return [jaxgrasp.Grasp.create(**{k: v[i] for k, v in out.items()}) for i in range(SAMPLES)]


def timed(fn) -> tuple[float, object]:
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


def main() -> None:
    jaxgrasp.engine.enable_compilation_cache()
    load0 = os.getloadavg()
    print(f"jax {jax.__version__}, devices {jax.devices()}, load average at start {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}")
    grasp = jaxgrasp.presets.prism(mass=0.1)
    u = jaxgrasp.analysis.parse_spec(SPEC)
    sets = {"random": random_grasps(), "prisms": prisms(), "copies": copies(grasp, u)}
    runs = {"robust": lambda: jaxgrasp.robust(grasp, u, samples=SAMPLES, seed=0),
            "nominal": lambda: jaxgrasp.evaluate(grasp)}
    runs.update({name: (lambda gs=gs: jaxgrasp.evaluate_batch(gs)) for name, gs in sets.items()})
    for name, fn in runs.items():  # warm: compile (or load) every program once
        t, out = timed(fn)
        print(f"warm-up {name}: {t:.2f} s", flush=True)
    times = {name: [] for name in runs}
    for k in range(REPEATS):
        for name, fn in runs.items():
            t, out = timed(fn)
            times[name].append(t)
            print(f"run {k + 1} {name}: {t:.3f} s", flush=True)
    r = runs["robust"]()
    print(f"robust: p_stable {r.p_stable:.4f} +- {r.p_stable_stderr:.4f}, value_mean {r.value_mean:.4e} J, "
          f"q05 {r.quantile(0.05):.4e} J, nominal {float(r.nominal.value):.4e} J ({r.nominal.status_name}), "
          f"{r.converged}/{SAMPLES} settled, clipped {r.clipped}")
    for name in sets:
        print(f"{name}: {runs[name]().counts()}")
    med = {name: statistics.median(ts) for name, ts in times.items()}
    best = {name: min(ts) for name, ts in times.items()}
    print(f"median of {REPEATS}: " + ", ".join(f"{name} {t:.3f} s" for name, t in med.items()))
    print(f"fastest of {REPEATS}: " + ", ".join(f"{name} {t:.3f} s" for name, t in best.items()))
    for name in sets:
        print(f"ratio robust ({SAMPLES} samples) / {name} ({SAMPLES} distinct grasps): fastest "
              f"{best['robust'] / best[name]:.3f}, median {med['robust'] / med[name]:.3f} (done-when: at most 1.5)")
    load1 = os.getloadavg()
    print(f"load average at end {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}")


if __name__ == "__main__":
    main()
