"""``jaxgrasp evaluate --robust SPEC`` and ``jaxgrasp batch --robust SPEC`` (issue 39): the
JSON fields and the CSV columns, equal to :func:`jaxgrasp.robust` of the same grasps, seed
and samples; one-line errors for a bad spec. 2-contact grasps in chunks of 4 only (the
programs ``tests/analysis/test_robust.py`` and ``tests/tolerance`` use)."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

import jaxgrasp
from jaxgrasp.analysis import Uncertainty

SPEC = "friction=0.2,position=1e-3"
U = Uncertainty(friction=0.2, position=1e-3)
ROBUST = ["--robust", SPEC, "--samples", "4", "--seed", "2", "--chunk-size", "4"]


@pytest.mark.slow  # evaluates (the 2-contact programs)
def test_evaluate_json_carries_the_robust_fields(run_cli):
    rc, out, err = run_cli(["evaluate", "--preset", "cube", "--mass", "0.2306", "--json", *ROBUST])
    assert rc == 0, err
    d = json.loads(out)
    grasp = jaxgrasp.presets.cube(mass=0.2306)
    r = jaxgrasp.robust(grasp, U, samples=4, seed=2, chunk_size=4)
    for key in ("p_stable", "p_stable_stderr", "value_mean", "value_q05", "value_q50"):
        assert d[key] == pytest.approx(getattr(r, key) if hasattr(r, key) else r.quantile(float(key[-2:]) / 100),
                                       rel=1e-12, abs=1e-18), key
    assert d["robust"]["samples"] == 4 and d["robust"]["seed"] == 2 and d["robust"]["robust_status"] == "estimated"
    assert d["robust"]["uncertainty"]["friction"] == 0.2 and d["robust"]["clipped"]["friction"] == 0
    assert d["status"] == "stable" and d["value"] == pytest.approx(float(jaxgrasp.evaluate(grasp).value), rel=1e-12)
    rc, out, err = run_cli(["evaluate", "--preset", "cube", "--mass", "0.2306", *ROBUST])
    assert rc == 0 and "p_stable: " in out and "robust: friction=0.2,position=0.001; 4 samples, seed 2" in out


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--robust", "friction=abc"], "--robust: uncertainty spec: friction = 'abc' is not a number"),
        (["--robust", "stiffness=0.1"], "--robust: uncertainty spec: unknown source 'stiffness'"),
        (["--robust", "friction=0.1", "--samples", "1"], "--samples must be >= 2, got 1"),
        (["--robust", "position=-1e-3"], "--robust: Uncertainty position = -0.001 m must be >= 0 and finite"),
    ],
)
def test_bad_robust_options_are_one_line_errors(run_cli, argv, message):
    rc, out, err = run_cli(["evaluate", "--preset", "cube", *argv])
    assert rc == 2 and out == ""
    assert err.strip() == f"jaxgrasp: error: {message}" or message in err and err.count("\n") == 1, err


@pytest.mark.slow  # evaluates (the 2-contact programs)
def test_batch_writes_the_robust_columns(run_cli, tmp_path):
    grasps = [jaxgrasp.presets.cube(mass=m, young_modulus=e) for m in (0.2306, 0.1) for e in (2e5, 3e5)]  # a chunk
    dataset = tmp_path / "set.jsonl"
    jaxgrasp.save_dataset(dataset, grasps)
    rc, out, err = run_cli(["batch", dataset, "--out", tmp_path / "o", "--no-plot", "--quiet", *ROBUST])
    assert rc == 0, err
    with open(tmp_path / "o" / "results.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    rb = jaxgrasp.robust_batch(grasps, U, samples=4, seed=2, chunk_size=4)
    for i, row in enumerate(rows):
        for key in ("p_stable", "value_mean", "value_q05"):
            assert float(row[key]) == pytest.approx(float(rb.columns()[key][i]), rel=1e-12, abs=1e-18), (i, key)
    assert "robust: friction=0.2,position=0.001; 4 samples per grasp, seed 2" in out
    assert np.load(tmp_path / "o" / "results.npz")["p_stable"].shape == (4,)
