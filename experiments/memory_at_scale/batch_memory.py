"""Peak memory of ``jaxgrasp batch`` against the number of grasps (issue 40, "Lines are lines").

Writes cube-like datasets (the paper's cube, two contacts, Young's modulus and initial
deformation varied so that the grasps differ) of ``--small`` and ``--large`` grasps as
``.npz`` (or ``.jsonl`` with ``--format jsonl``) in a temporary folder, runs the command
line on each in a subprocess (``python -m jaxgrasp batch FILE --out DIR``, every output
written, the picture too) and reads each child's peak resident memory from
``os.wait4``'s resource usage. A first run on a few grasps fills a private compilation
cache, so that both measured runs load the same compiled program instead of one of them
compiling it.

Prints, and appends to ``--log``: the grasp counts, peak RSS of each run (MiB), their
ratio (issue 40 asks for at most 1.5 between 200,000 and 20,000 grasps), wall times and
the load average before and after.

    python experiments/memory_at_scale/batch_memory.py                     # 20,000 and 200,000 grasps
    python experiments/memory_at_scale/batch_memory.py --small 2000 --large 20000   # a quick look
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def cube_arrays(n: int, seed: int = 0) -> dict[str, np.ndarray]:
    """``n`` cube grasps as dataset arrays (the ``.npz`` format of ``jaxgrasp.load_dataset``):
    contacts at the centres of the cube's +-x faces (m), E in [2e5, 1e6] Pa, initial
    deformation in [1, 3] mm, fingertip radius 25 mm, friction 0.5, 15 N, no mass."""
    rng = np.random.default_rng(seed)
    positions = np.broadcast_to(np.array([[0.05, 0.0, 0.0], [-0.05, 0.0, 0.0]]), (n, 2, 3))
    normals = np.broadcast_to(np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]]), (n, 2, 3))
    return {
        "positions": np.ascontiguousarray(positions),
        "normals": np.ascontiguousarray(normals),
        "initial_deformation": rng.uniform(1e-3, 3e-3, n),
        "radius": np.float64(0.025),
        "young_modulus": rng.uniform(2e5, 1e6, n),
        "friction": np.float64(0.5),
        "max_force": np.float64(15.0),
    }


def write_dataset(folder: Path, n: int, fmt: str) -> Path:
    """A dataset file of ``n`` cube grasps in ``folder`` (``.npz`` or ``.jsonl``)."""
    arrays = cube_arrays(n)
    path = folder / f"cubes_{n}.{fmt}"
    if fmt == "npz":
        np.savez(path, **arrays)
        return path
    with open(path, "w", encoding="utf-8") as fh:
        for i in range(n):
            line = {
                "fingertip": {"radius": 0.025, "young_modulus": float(arrays["young_modulus"][i]),
                              "friction": 0.5, "max_force": 15.0},
                "contacts": [
                    {"position": [0.05, 0.0, 0.0], "normal": [1.0, 0.0, 0.0],
                     "initial_deformation": float(arrays["initial_deformation"][i])},
                    {"position": [-0.05, 0.0, 0.0], "normal": [-1.0, 0.0, 0.0],
                     "initial_deformation": float(arrays["initial_deformation"][i])},
                ],
            }
            fh.write(json.dumps(line) + "\n")
    return path


def run_batch(path: Path, out: Path, env: dict) -> tuple[float, float, str]:
    """``(peak RSS MiB, wall s, last stdout line)`` of ``jaxgrasp batch path --out out``."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(
        [sys.executable, "-m", "jaxgrasp", "batch", str(path), "--out", str(out), "--quiet"],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    )
    stdout = proc.stdout.read()
    stderr = proc.stderr.read()
    _, status, usage = os.wait4(proc.pid, 0)  # this child's own peak, not the largest child's so far
    proc.returncode = os.waitstatus_to_exitcode(status)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"batch {path.name} failed ({proc.returncode}): {stderr.decode()[-2000:]}")
    peak_mib = usage.ru_maxrss / 1024  # Linux: KiB
    return peak_mib, wall, stdout.decode().splitlines()[0]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--small", type=int, default=20_000)
    p.add_argument("--large", type=int, default=200_000)
    p.add_argument("--format", choices=("npz", "jsonl"), default="npz")
    p.add_argument("--log", type=Path, default=HERE / "batch_memory.log")
    args = p.parse_args()
    head = (f"# {time.strftime('%Y-%m-%d %H:%M:%S')} batch_memory.py --small {args.small} --large {args.large} "
            f"--format {args.format}; PYTHONPATH={os.environ.get('PYTHONPATH', '')}; "
            f"load average before {os.getloadavg()}")
    lines = [head]
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        env = dict(os.environ, JAXGRASP_CACHE_DIR=str(folder / "cache"))
        warm = write_dataset(folder, 100, args.format)
        run_batch(warm, folder / "out-warm", env)  # compiles and stores the program both runs use
        peaks = {}
        for n in (args.small, args.large):
            path = write_dataset(folder, n, args.format)
            peak, wall, summary = run_batch(path, folder / f"out-{n}", env)
            peaks[n] = peak
            lines.append(f"{n} grasps ({path.stat().st_size / 2**20:.1f} MiB {args.format}): peak RSS {peak:.0f} MiB, "
                         f"wall {wall:.0f} s, load average after {os.getloadavg()}")
            lines.append(f"  {summary}")
    ratio = peaks[args.large] / peaks[args.small]
    lines.append(f"ratio peak({args.large}) / peak({args.small}) = {ratio:.3f} (issue 40: at most 1.5)")
    text = "\n".join(lines) + "\n"
    print(text, end="")
    with open(args.log, "a", encoding="utf-8") as fh:
        fh.write(text)


if __name__ == "__main__":
    main()
