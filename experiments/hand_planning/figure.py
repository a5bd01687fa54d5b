"""The figure and the comparison numbers of the hand-planning benchmark, from its logs.

Reads ``value.jsonl``, ``epsilon.jsonl`` and ``random.jsonl`` (one line per object, written by
``plan_hand_benchmark.py --json``) beside this file; writes ``figure.png``: (a) per arm, the
share of objects with a stable best grasp and with a stable one of three or more fingertips;
(b) per object planned both ways, the energy tolerance of the grasp each objective picked;
(c) the same for epsilon; (d) seconds per object. Prints the comparison.

    python experiments/hand_planning/figure.py
"""

import json
import statistics
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ARMS = ("value", "epsilon", "random")


def _rows(arm: str) -> dict:
    path = HERE / f"{arm}.jsonl"
    if not path.is_file():
        return {}
    return {r["object"]: r for r in map(json.loads, path.read_text().splitlines())}


def _shares(rows: dict) -> tuple[float, float]:
    n = len(rows)
    stable = sum(r["stable"] for r in rows.values())
    three = sum(r["stable"] and r["active"] >= 3 for r in rows.values())
    return 100 * stable / n, 100 * three / n


def compare(arms: dict) -> list[str]:
    """Lines of the comparison: shares, times, and how the value's and epsilon's picks differ."""
    lines = []
    for arm, rows in arms.items():
        if rows:
            s, t = _shares(rows)
            secs = [r["seconds"] for r in rows.values()]
            lines.append(f"{arm}: {len(rows)} objects, stable best {s:.0f} %, stable with >= 3 fingertips {t:.0f} %, "
                         f"median {statistics.median(secs):.1f} s per object (max {max(secs):.1f}), candidates "
                         f"{next(iter(rows.values())).get('candidates')}")
    v, e = arms["value"], arms["epsilon"]
    both = sorted((k for k in v if k in e and v[k]["value_J"] > 0), key=str)
    if both:
        value_ratio = np.array([e[k]["value_J"] / v[k]["value_J"] for k in both])
        eps_ratio = np.array([v[k]["epsilon"] / e[k]["epsilon"] for k in both])
        same = sum(v[k]["value_J"] == e[k]["value_J"] and v[k]["epsilon"] == e[k]["epsilon"] for k in both)
        lines.append(
            f"value against epsilon on {len(both)} objects: the same best grasp on {same}; the epsilon-picked grasp's "
            f"energy tolerance is {np.median(value_ratio):.3f} (median, 0 where it is unstable: "
            f"{int(np.sum(value_ratio == 0))} objects; quartiles {np.quantile(value_ratio, 0.25):.3f}-"
            f"{np.quantile(value_ratio, 0.75):.3f}) of the value-picked one's, below it on "
            f"{int(np.sum(value_ratio < 1))}; the value-picked grasp's epsilon is {np.median(eps_ratio):.2f} (median; "
            f"quartiles {np.quantile(eps_ratio, 0.25):.2f}-{np.quantile(eps_ratio, 0.75):.2f}) of the epsilon-picked "
            f"one's")
    r = arms["random"]
    common = sorted((k for k in r if k in v), key=str)
    if common:
        lines.append(f"value planner against random closed-hand sampling on the {len(common)} objects of both: stable best "
                     f"{sum(v[k]['stable'] for k in common)} against {sum(r[k]['stable'] for k in common)}, with >= 3 "
                     f"fingertips {sum(v[k]['stable'] and v[k]['active'] >= 3 for k in common)} against "
                     f"{sum(r[k]['stable'] and r[k]['active'] >= 3 for k in common)}; median best value "
                     f"{np.median([v[k]['value_J'] for k in common]):.3e} J against "
                     f"{np.median([r[k]['value_J'] for k in common]):.3e} J; the planner's best over random's: median "
                     f"{np.median([v[k]['value_J'] / r[k]['value_J'] for k in common]):.2f}, least "
                     f"{min(v[k]['value_J'] / r[k]['value_J'] for k in common):.2f}; median time "
                     f"{np.median([v[k]['seconds'] for k in common]):.0f} s against "
                     f"{np.median([r[k]['seconds'] for k in common]):.0f} s")
    return lines


def figure(arms: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    fig, ax = plt.subplots(1, 4, figsize=(17, 4.2))
    present = [a for a in ARMS if arms[a]]
    shares = np.array([_shares(arms[a]) for a in present])
    x = np.arange(len(present))
    ax[0].bar(x - 0.2, shares[:, 0], 0.4, label="stable best")
    ax[0].bar(x + 0.2, shares[:, 1], 0.4, label="stable, >= 3 fingertips")
    ax[0].set_xticks(x, [f"{a}\n({len(arms[a])} objects)" for a in present])
    ax[0].set_ylabel("objects, %")
    ax[0].set_ylim(0, 105)
    ax[0].legend(loc="lower right", fontsize=8)
    ax[0].set_title("(a) share of objects")
    v, e = arms["value"], arms["epsilon"]
    both = sorted((k for k in v if k in e and v[k]["value_J"] > 0 and e[k]["value_J"] > 0), key=str)
    for a, key, title, unit in ((ax[1], "value_J", "(b) energy tolerance of the pick", "J"),
                                (ax[2], "epsilon", "(c) epsilon of the pick", "")):
        keys = both if key == "value_J" else sorted((k for k in v if k in e), key=str)
        xs, ys = np.array([v[k][key] for k in keys]), np.array([e[k][key] for k in keys])
        a.scatter(xs, ys, s=14)
        lo, hi = min(xs.min(), ys.min()), max(xs.max(), ys.max())
        a.plot([lo, hi], [lo, hi], "k--", lw=0.8, label="equal")
        if key == "value_J":
            a.set_xscale("log")
            a.set_yscale("log")
            a.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())  # the minor labels overlapped
        a.set_xlabel(f"picked by the value{', ' + unit if unit else ''}")
        a.set_ylabel(f"picked by epsilon{', ' + unit if unit else ''}")
        a.set_title(title + (f" ({sum(e[k]['value_J'] == 0 for k in v if k in e)} epsilon picks unstable: "
                             "value 0, not drawn)" if key == "value_J" else ""), fontsize=9)
        a.legend(fontsize=8)
    for arm in present:
        secs = sorted(r["seconds"] for r in arms[arm].values())
        ax[3].plot(secs, np.arange(1, len(secs) + 1) / len(secs), label=arm)
    ax[3].axvline(180, color="k", ls=":", lw=0.8, label="180 s")
    ax[3].set_xlabel("seconds per object (2 cores)")
    ax[3].set_ylabel("fraction of objects")
    ax[3].set_title("(d) time per object")
    ax[3].legend(fontsize=8)
    names = {"value": "planning for the energy tolerance", "epsilon": "for epsilon",
             "random": "random closed-hand sampling"}
    fig.suptitle("Shadow hand on pybullet objects (70 mm): " + ", ".join(names[a] for a in present))
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    arms = {a: _rows(a) for a in ARMS}
    for line in compare(arms):
        print(line)
    figure(arms, HERE / "figure.png")
    print(f"wrote {HERE / 'figure.png'}")


if __name__ == "__main__":
    sys.exit(main())
