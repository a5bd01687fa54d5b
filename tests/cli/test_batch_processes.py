"""``jaxgrasp batch`` over processes joined by ``jax.distributed`` (issue 41, item 5).

Two processes on localhost, one CPU device each, joined by ``--coordinator``,
``--num-processes 2`` and ``--process-id`` with gloo collectives, run the real command on
one dataset: each reads and evaluates its own share (every other grasp) and process 0
writes one ``results.csv`` in input order. It must be the file a run of one process
writes, byte for byte, and its values those of ``evaluate`` of every grasp; process 1
writes nothing to ``--out``. The dataset holds an invalid line and a blank one, so that
the errors and line numbers of one share land in the right rows.

Cost: both processes compile the batch's program at once (process 1 stores its own, its
device ids being its own); the run of one process then loads process 0's. The set is
of 2-contact grasps in chunks of 4, one program for all three runs (padding has its
own tests, ``tests/engine/test_padding.py``). The options' errors and the reading of a
share run in this process, without a compilation.
"""

from __future__ import annotations

import csv
import json
import os
import socket
import subprocess
import sys

import numpy as np
import pytest

import jaxgrasp
from jaxgrasp.io._dataset import load_dataset, load_share, padded_set

E = [2e5, 6e5, 1e6]
DR = [1e-3, 2e-3]
BAD = 3  # the invalid grasp's index: in process 1's share


def _grasps():
    return [jaxgrasp.presets.cube(young_modulus=e, initial_deformation=d) for e in E for d in DR]


def _dataset(folder):
    """A .jsonl of the six grasps, an invalid one (friction -1) as grasp 3, a blank line before it."""
    path = folder / "set.jsonl"
    jaxgrasp.save_dataset(path, _grasps())
    lines = path.read_text().splitlines()
    bad = json.loads(lines[0])
    bad["fingertip"]["friction"] = -1
    lines[BAD:BAD] = ["", json.dumps(bad)]
    path.write_text("\n".join(lines) + "\n")
    return path


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _env():
    # one CPU device per process (import jaxgrasp would otherwise make one per core)
    env = dict(os.environ, JAX_PLATFORMS="cpu", JAXGRASP_CPU_DEVICES="1")
    env.pop("XLA_FLAGS", None)
    return env


def _batch(*args):
    return [sys.executable, "-m", "jaxgrasp", "batch", *map(str, args), "--chunk-size", "4", "--no-plot"]


def _two_processes(argv, cwd):
    """Run ``argv`` as processes 0 and 1 of two at once; their (exit status, stdout, stderr)."""
    port = _free_port()
    procs = [
        subprocess.Popen(argv + ["--coordinator", f"127.0.0.1:{port}", "--num-processes", "2", "--process-id", str(i)],
                         env=_env(), cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        for i in range(2)
    ]
    try:
        outs = [p.communicate(timeout=300) for p in procs]
        return [(p.returncode, *o) for p, o in zip(procs, outs)]
    finally:
        for p in procs:
            p.kill()


def _rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_two_processes_write_what_one_does(tmp_path, evaluate_many):
    data = _dataset(tmp_path)
    (rc0, out0, err0), (rc1, out1, err1) = _two_processes(_batch(data, "--out", "two"), tmp_path)
    assert rc0 == 0 and rc1 == 0, err0[-3000:] + err1[-3000:]
    assert "(2 processes, 2 devices:" in out0.splitlines()[0], out0  # one device each, joined
    assert out1.startswith("batch ") and "process 1 of 2 (1 of 2 devices): evaluated 2 grasps of its share" in out1
    assert "[Gloo]" not in out0 + out1  # gloo's connection lines go to stderr: stdout is the summary
    assert sorted(p.name for p in (tmp_path / "two").iterdir()) == ["results.csv", "results.npz"]

    one = subprocess.run(_batch(data, "--out", "one", "--quiet"), env=_env(), cwd=tmp_path,
                         capture_output=True, text=True, timeout=300)
    assert one.returncode == 0, one.stderr[-3000:]
    assert "jaxgrasp: compiling" not in one.stderr, one.stderr  # process 0's stored program: the same one
    assert (tmp_path / "two" / "results.csv").read_bytes() == (tmp_path / "one" / "results.csv").read_bytes()
    a, b = np.load(tmp_path / "one" / "results.npz"), np.load(tmp_path / "two" / "results.npz")
    for k in set(a.files) - {"compile_seconds", "run_seconds", "devices"}:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)

    rows = _rows(tmp_path / "two" / "results.csv")
    assert [r["index"] for r in rows] == [str(i) for i in range(7)]
    assert rows[BAD]["status"] == "invalid"
    assert rows[BAD]["error"] == f"grasp {BAD} (line {BAD + 2}): friction = -1 must be positive and finite"
    good = [r for r in rows if r["status"] != "invalid"]
    for row, ref in zip(good, evaluate_many(_grasps()), strict=True):
        assert row["status"] == ref.status_name
        np.testing.assert_allclose(float(row["value_J"]), float(ref.value), rtol=1e-12, atol=1e-18)
        np.testing.assert_allclose(float(row["equilibrium_energy_J"]), float(ref.equilibrium_energy), rtol=1e-12)
        assert int(row["limiting_contact"]) == int(ref.limiting_contact)
    assert all(float(r["value_J"]) > 0 for r in good)  # every grasp stable: the comparison is not of zeros


def test_a_failing_process_ends_both_with_one_line(tmp_path):
    """--strict: only process 1's share holds the invalid grasp; both end at the first
    meeting, before anything compiles, process 0 naming process 1."""
    data = _dataset(tmp_path)
    (rc0, out0, err0), (rc1, out1, err1) = _two_processes(_batch(data, "--out", "o", "--strict"), tmp_path)
    assert (rc0, rc1, out0, out1) == (2, 2, "", ""), err0 + err1
    assert f"jaxgrasp: error: process 1 of 2 failed: {data}: grasp {BAD} (line {BAD + 2}): friction" in err0, err0
    assert f"jaxgrasp: error: {data}: grasp {BAD} (line {BAD + 2}): friction" in err1, err1
    assert "compiling" not in err0 + err1
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").glob("results*"))


def test_a_share_is_the_rows_of_the_whole_set(tmp_path):
    """Each share holds its rows of the whole set (errors naming the input index and
    line), and padded to the set's contact count its columns are the set's rows."""
    grasps = [jaxgrasp.presets.cube(), jaxgrasp.presets.prism(), jaxgrasp.presets.cube(6e5, 0.002)]
    path = tmp_path / "mixed.jsonl"
    jaxgrasp.save_dataset(path, grasps)
    lines = path.read_text().splitlines()
    lines.insert(1, '{"fingertip": 1}')  # invalid, grasp 1 (line 2)
    path.write_text("\n".join(lines) + "\n")
    whole = load_dataset(path)
    cols = whole.columns()
    for index, count in [(0, 2), (1, 2), (2, 3), (0, 5), (4, 5)]:
        share, total = load_share(path, index, count)
        rows = np.arange(index, len(whole), count)
        assert total == len(whole) == 4
        assert share.errors == tuple(whole.errors[i] for i in rows)
        assert share.source_sha256 == whole.source_sha256
        padded = padded_set(share, cols.fields["positions"].shape[1]).columns()
        np.testing.assert_array_equal(padded.counts, cols.counts[rows])
        valid = cols.counts[rows] > 0
        for name, a in padded.fields.items():
            np.testing.assert_array_equal(a[valid], cols.fields[name][rows][valid], err_msg=name)


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--num-processes", "2"], "--coordinator, --num-processes and --process-id go together: --coordinator, --process-id missing"),
        (["--coordinator", "localhost", "--num-processes", "2", "--process-id", "0"], "--coordinator must be HOST:PORT"),
        (["--coordinator", "h:70000", "--num-processes", "2", "--process-id", "0"], "--coordinator must be HOST:PORT"),
        (["--coordinator", "h:1", "--num-processes", "0", "--process-id", "0"], "--num-processes must be >= 1, got 0"),
        (["--coordinator", "h:1", "--num-processes", "2", "--process-id", "2"], "--process-id must be in 0..1, got 2"),
        (["--coordinator", "h:1", "--num-processes", "2", "--process-id", "1", "--resume"], "--resume finishes a run of one process"),
    ],
)
def test_process_options_that_do_not_go_together(run_cli, tmp_path, argv, message):
    data = _dataset(tmp_path)
    rc, out, err = run_cli(["batch", data, "--out", tmp_path / "o", *argv])
    assert rc == 2 and out == "" and err.count("\n") == 1, err
    assert err.startswith(f"jaxgrasp: error: {message}"), err
    assert not (tmp_path / "o").exists()
