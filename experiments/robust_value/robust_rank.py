"""Do the nominal and the robust rankings of grasps agree? (issue 39's finding)

1000 seeded random 3-contact grasps (``tests/grasp_draws.py:build_grasp``, seed 0: three
fingertips on a sphere or a box, random fingertips, half of them with a mass up to half of
what friction carries, gravity in a random direction; stable or not, as drawn) are ranked
by their nominal value (:meth:`jaxgrasp.BatchResult.rank`) and by their robust mean value
(:func:`jaxgrasp.robust_batch`, ``value_mean``) under the issue's uncertainty
``friction=0.1,young_modulus=0.1,initial_deformation=2e-4,position=1e-3``. The script
prints how many of the nominal top 10 % stay in the robust top 10 % (and in the top by
``p_stable`` and by the 0.05 quantile), the Monte Carlo noise floor of that overlap (the
robust top 10 % of the first half of the samples against that of the second half, with
the same grasps), examples of grasps that leave and enter the top, and draws the figure
``experiments/robust_value/robust_rank.png``; the per-grasp numbers go to
``experiments/robust_value/robust_rank.csv``.

``--samples`` (default 16) keeps the run within about 6 minutes of CPU on 2 cores:
1000 x 16 sample evaluations and 1000 nominal ones. Run:
``python experiments/robust_value/robust_rank.py`` (log: ``experiments/robust_value/robust_rank.log``).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT  # noqa: E402

import jaxgrasp  # noqa: E402
from _lab.grasp_draws import NumpyDraw, build_grasp  # noqa: E402

FIGURES = Path(__file__).resolve().parent  # the study folder
SPEC = "friction=0.1,young_modulus=0.1,initial_deformation=2e-4,position=1e-3"


def top(order: np.ndarray, k: int) -> set[int]:
    return {int(i) for i in order[:k]}


def spearman(a: np.ndarray, b: np.ndarray) -> float:
    ra, rb = np.argsort(np.argsort(a)), np.argsort(np.argsort(b))
    return float(np.corrcoef(ra, rb)[0, 1])


def half_rank(rb, half: slice) -> np.ndarray:
    """The ranking by the mean value over one half of the samples (settled ones only)."""
    v, s = rb.values[:, half], rb.statuses[:, half]
    ok = s != jaxgrasp.GraspStatus.NOT_CONVERGED
    mean = np.where(ok.any(axis=1), (v * ok).sum(axis=1) / np.maximum(ok.sum(axis=1), 1), -np.inf)
    return np.lexsort((np.arange(len(mean)), -mean))


def report(grasps, nominal, rb, k: int) -> dict:
    """Print the overlaps, the noise floor and the correlations; return the top sets."""
    nom = nominal.rank()
    sets = {"nominal": top(nom, k)}
    for by in ("value_mean", "p_stable", "value_q05"):
        sets[by] = top(rb.rank(by), k)
        same = len(sets["nominal"] & sets[by])
        print(f"top {k} by nominal value vs top {k} by robust {by}: {same} shared, {k - same} differ "
              f"({100 * (k - same) / k:.0f} % disagree)")
    s = rb.samples // 2
    a, b = top(half_rank(rb, slice(0, s)), k), top(half_rank(rb, slice(s, None)), k)
    print(f"noise floor: top {k} by value_mean over samples 0-{s - 1} vs over samples {s}-{rb.samples - 1}: "
          f"{len(a & b)} shared, {k - len(a & b)} differ")
    stable = np.asarray(nominal.status) == jaxgrasp.GraspStatus.STABLE
    print(f"nominal statuses: {nominal.counts()}; robust statuses: {jaxgrasp.analysis.RobustStatus.count(rb.status)}")
    print(f"Spearman(nominal value, value_mean) over the {stable.sum()} nominally stable grasps: "
          f"{spearman(np.asarray(nominal.value)[stable], rb.value_mean[stable]):+.3f}")
    knife = stable & (rb.p_stable < 0.5)
    print(f"nominally stable grasps with p_stable < 0.5: {knife.sum()}; in the nominal top {k}: "
          f"{len(sets['nominal'] & set(np.flatnonzero(knife).tolist()))}")
    print(f"nominally not stable grasps with p_stable > 0: {(~stable & (rb.p_stable > 0)).sum()}")
    return sets


def examples(nominal, rb, sets: dict, k: int, count: int = 4) -> None:
    """The grasps that leave the top (nominal rank, robust rank, numbers) and enter it."""
    nrank = np.empty(len(rb), int)
    nrank[nominal.rank()] = np.arange(len(rb))
    rrank = np.empty(len(rb), int)
    rrank[rb.rank("value_mean")] = np.arange(len(rb))
    value = np.asarray(nominal.value)
    for title, ids in (("leave the top (nominal top, robust not)", sets["nominal"] - sets["value_mean"]),
                       ("enter the top (robust top, nominal not)", sets["value_mean"] - sets["nominal"])):
        ids = sorted(ids, key=lambda i: nrank[i] if "leave" in title else rrank[i])[:count]
        print(f"examples that {title}:")
        for i in ids:
            r = rb[i]
            print(f"  grasp {i}: nominal rank {nrank[i] + 1}, value {value[i]:.3e} J, "
                  f"limited by {nominal.limiting_kind_names[i]}; robust rank {rrank[i] + 1}, "
                  f"value_mean {r.value_mean:.3e} J, q05 {r.quantile(0.05):.3e} J, p_stable {r.p_stable:.3f}")


def figure(nominal, rb, sets: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    value = np.asarray(nominal.value)
    floor = 1e-9
    x, y = np.maximum(value, floor), np.maximum(rb.value_mean, floor)
    fig, ax = plt.subplots(figsize=(7, 5.5))
    sc = ax.scatter(x, y, c=rb.p_stable, cmap="viridis", s=10, vmin=0, vmax=1)
    fig.colorbar(sc, ax=ax, label="p_stable")
    for ids, marker, label in ((sets["nominal"] - sets["value_mean"], "v", "nominal top 10 %, not robust top"),
                               (sets["value_mean"] - sets["nominal"], "^", "robust top 10 %, not nominal top")):
        ids = sorted(ids)
        ax.scatter(x[ids], y[ids], facecolors="none", edgecolors="red" if marker == "v" else "black",
                   marker=marker, s=60, label=label)
    lim = [floor, max(x.max(), y.max()) * 2]
    ax.plot(lim, lim, color="grey", lw=0.8, ls="--")
    ax.set(xscale="log", yscale="log", xlim=lim, ylim=lim, xlabel="nominal value [J] (0 drawn at 1e-9)",
           ylabel="robust mean value [J]", title=f"{len(rb)} random 3-contact grasps, {rb.samples} samples: {SPEC}")
    ax.title.set_fontsize(8)
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def write_csv(path: Path, nominal, rb) -> None:
    cols = rb.columns()
    header = ["index", "nominal_value_J", "nominal_status"] + list(cols) + ["robust_status"]
    with open(path, "w") as fh:
        fh.write(",".join(header) + "\n")
        for i in range(len(rb)):
            row = [str(i), repr(float(nominal.value[i])), nominal.status_names[i]]
            row += [repr(float(c[i])) for c in cols.values()] + [rb.status_names[i]]
            fh.write(",".join(row) + "\n")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--count", type=int, default=1000)
    p.add_argument("--samples", type=int, default=16)
    args = p.parse_args()
    jaxgrasp.engine.enable_compilation_cache()
    FIGURES.mkdir(exist_ok=True)
    load0 = os.getloadavg()
    print(f"{args.count} grasps x {args.samples} samples, {SPEC}; load average at start {load0[0]:.2f}")
    rng = np.random.default_rng(0)
    grasps = [build_grasp(NumpyDraw(rng), n=3) for _ in range(args.count)]
    t0, c0 = time.perf_counter(), time.process_time()
    rb = jaxgrasp.robust_batch(grasps, jaxgrasp.analysis.parse_spec(SPEC), args.samples, seed=0)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    print(f"robust_batch: wall {wall:.1f} s, CPU {cpu:.1f} s (this process, every thread), "
          f"{args.count * (args.samples + 1) / wall:.1f} evaluations per second")
    k = args.count // 10
    sets = report(grasps, rb.nominal, rb, k)
    examples(rb.nominal, rb, sets, k)
    figure(rb.nominal, rb, sets, FIGURES / "robust_rank.png")
    write_csv(FIGURES / "robust_rank.csv", rb.nominal, rb)
    load1 = os.getloadavg()
    print(f"wrote {FIGURES / 'robust_rank.png'} and robust_rank.csv; load average at end {load1[0]:.2f}")


if __name__ == "__main__":
    main()
