"""What breaks if jaxgrasp enabled float64 only around its own calls instead of process-wide.

``import jaxgrasp`` sets ``jax_enable_x64`` for the whole process. The less intrusive
alternative (issue 10) is to leave the user's setting alone and enable x64 only inside
jaxgrasp's own entry points (``with jax.enable_x64(True):`` around ``Grasp.create`` and
``evaluate``). This script runs the same user snippets in two fresh processes:

* ``global``: ``import jaxgrasp`` as shipped (x64 on for the process);
* ``scoped``: x64 off for the process after the import, and jaxgrasp's ``Grasp.create``
  and ``evaluate`` wrapped in ``jax.enable_x64(True)`` (what a scoped design would do);

and prints, per snippet, the dtype of the result, its relative difference from the
float64 value, or the exception. Run: ``python experiments/startup/x64_scope.py``
(about 3 minutes on 2 cores; the log is ``experiments/startup/x64_scope.log``).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

WORKER = textwrap.dedent(
    r"""
    import json, sys, functools
    import jax, jax.numpy as jnp, numpy as np
    import jaxgrasp
    mode = sys.argv[1]
    if mode == "scoped":
        jax.config.update("jax_enable_x64", False)
        def scoped(fn):
            @functools.wraps(fn)
            def wrapper(*a, **k):
                with jax.enable_x64(True):
                    return fn(*a, **k)
            return wrapper
        jaxgrasp.Grasp.create = classmethod(scoped(jaxgrasp.Grasp.create.__func__))
        jaxgrasp.evaluate = scoped(jaxgrasp.evaluate)
        jaxgrasp.presets.cube = scoped(jaxgrasp.presets.cube)
    REF = 2.638202983905735e-4  # J, cube E = 6e5 Pa, dr = 2 mm, float64
    REF_GRAD = None
    out = {}

    def record(name, fn):
        try:
            v = fn()
            a = np.asarray(v)
            out[name] = {"dtype": str(a.dtype), "value": float(a.reshape(-1)[0])}
        except Exception as exc:
            out[name] = {"error": type(exc).__name__ + ": " + " ".join(str(exc).split())[:160]}

    g = jaxgrasp.presets.cube(6e5, 2e-3)
    record("Grasp.create dtype (young_modulus)", lambda: g.young_modulus)
    record("evaluate(g).value", lambda: jaxgrasp.evaluate(g).value)
    record("jax.jit(evaluate)(g).value", lambda: jax.jit(jaxgrasp.evaluate)(g).value)
    gb = jax.tree_util.tree_map(lambda a: jnp.stack([a, a]), g)
    record("jax.vmap(evaluate)(batch).value", lambda: jax.vmap(jaxgrasp.evaluate)(gb).value)
    record(
        "jax.grad(value)(young_modulus) [J/Pa]",
        lambda: jax.grad(lambda e: jaxgrasp.evaluate(g.replace(young_modulus=e)).value)(g.young_modulus),
    )
    record("user's own jnp.zeros(3) after import", lambda: jnp.zeros(3))
    record("user's own jnp.arange(3.0) after import", lambda: jnp.arange(3.0))
    print("RESULT " + json.dumps(out))
    """
)


def run(mode: str) -> dict:
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    env.pop("JAX_ENABLE_X64", None)
    proc = subprocess.run([sys.executable, "-c", WORKER, mode], env=env, capture_output=True, text=True)
    for line in proc.stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line[len("RESULT "):])
    raise RuntimeError(f"{mode} worker failed:\n{proc.stderr[-2000:]}")


def main() -> None:
    ref_value = 2.638202983905735e-4
    results = {mode: run(mode) for mode in ("global", "scoped")}
    print(f"{'snippet':<42} {'global (as shipped)':<34} scoped x64 (alternative)")
    for name in results["global"]:
        cells = []
        for mode in ("global", "scoped"):
            r = results[mode][name]
            if "error" in r:
                cells.append(r["error"][:60])
                continue
            text = r["dtype"]
            if "value" in name and "grad" not in name:
                text += f", rel. diff {abs(r['value'] - ref_value) / ref_value:.1e}"
            if "grad" in name:
                text += f", {r['value']:.6e}"
            cells.append(text)
        print(f"{name:<42} {cells[0]:<34} {cells[1]}")
    print(
        "\nDecision: JAX fixes dtypes when it traces, in the caller's mode. With a scoped x64, "
        "the user's own jax.jit and jax.grad of evaluate mix float32 and float64 and fail "
        "(plain calls and vmap work), and the user's own arrays are float32; float64 by "
        "default therefore needs the process-wide flag. jaxgrasp keeps it, documents it at "
        "the top of the README, and leaves an explicit JAX_ENABLE_X64 in the environment "
        "alone (tests/model/test_x64.py)."
    )


if __name__ == "__main__":
    main()
