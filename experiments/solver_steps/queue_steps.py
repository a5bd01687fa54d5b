"""Loop steps and idle slots of the solver's work queue on the batch benchmark's mixed
set (issue 41): a count that does not depend on the machine's speed or load.

    python experiments/solver_steps/queue_steps.py [--count 1000] [--seed 0] [--max-steps 300] [--rho0 1]
        [--max-slots 128] [--slot-fraction 0.0625] [--chunk N --one-device] [--repeat-to N] [--save FILE.npz]

Every ``while_loop`` of the solver's work queue (the module of :func:`jaxgrasp.solver.solve_lanes`) is wrapped (in this process only)
so that it also counts its loop steps and, in each, the slots not running a lane; the
counts of every queue run come back through ``jax.debug.callback``. The set is
evaluated once with ``evaluate_batch`` (the executable store is off, so the wrapped
queue is what runs). Prints, per queue run, (loop steps, slots, idle slot-steps), then
the totals. Load average printed.
"""

from __future__ import annotations

import argparse
import os
import sys
import types
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared helpers (_lab)
from _lab import ROOT, reuse  # noqa: E402

reuse("batch_benchmark")  # the studies whose scripts this one imports

from _lab import say  # noqa: E402


def counting_queue(runs: list, max_steps: int):
    """Put a counting ``while_loop`` into the queue's module; ``runs`` receives one
    ``(loop steps, slots, idle slot-steps)`` per queue run (a slot is idle where its lane
    has ended or has taken the solver's ``max_steps``)."""
    import jax
    import jax.numpy as jnp

    import jaxgrasp.solver
    from _lab import module_of
    from jaxgrasp.solver import LaneStatus

    # no public hook counts the queue's loop steps: this instrument replaces the queue module's `jax`
    _lanes = module_of(jaxgrasp.solver.solve_lanes)

    def record(steps, slots, idle):
        runs.append((int(steps), int(slots), int(idle)))

    def while_loop(cond, body, init):
        def step(carry):
            q, k, idle = carry
            running = (q.slots.status == LaneStatus.NOT_CONVERGED) & (q.slots.steps < max_steps)
            return body(q), k + 1, idle + jnp.sum(~running).astype(jnp.int32)

        zero = jnp.asarray(0, jnp.int32)
        q, k, idle = jax.lax.while_loop(lambda c: cond(c[0]), step, (init, zero, zero))
        jax.debug.callback(record, k, jnp.asarray(q.idx.shape[0]), idle)
        return q

    lax = types.SimpleNamespace(**{k: getattr(jax.lax, k) for k in dir(jax.lax) if not k.startswith("__")})
    lax.while_loop = while_loop
    wrapped = types.SimpleNamespace(**{k: getattr(jax, k) for k in dir(jax) if not k.startswith("__")})
    wrapped.lax = lax
    _lanes.jax = wrapped


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--count", type=int, default=1000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--max-steps", type=int, default=None,
                   help="the solver's step budget per lane (default: SolverOptions' own)")
    p.add_argument("--rho0", type=float, default=None,
                   help="the solver's initial penalty (default: SolverOptions' own)")
    p.add_argument("--max-slots", type=int, default=None,
                   help="the queue's widest loop step (default: SolverOptions' own)")
    p.add_argument("--slot-fraction", type=float, default=None, help="slots per lane (default: SolverOptions' own)")
    p.add_argument("--chunk", type=int, default=None, help="grasps per compiled call (default: the engine's)")
    p.add_argument("--one-device", action="store_true", help="one CPU device, as one GPU is (default: every core)")
    p.add_argument("--repeat-to", type=int, default=None,
                   help="the set repeated to this many grasps (as gpu_slots.py repeats it for a wide chunk)")
    p.add_argument("--save", default=None, help="also write the grasps' statuses and values to this .npz")
    args = p.parse_args()
    import jaxgrasp
    from jaxgrasp.engine import set_executable_dir

    given = {k: v for k, v in (("max_steps", args.max_steps), ("rho0", args.rho0), ("max_slots", args.max_slots),
                               ("slot_fraction", args.slot_fraction)) if v is not None}
    solver = jaxgrasp.SolverOptions(**given)

    from batch_benchmark import make_grasps

    set_executable_dir(None)
    import jax

    devices = jax.devices()[:1] if args.one_device else None
    say(f"$ python experiments/solver_steps/queue_steps.py --count {args.count} --seed {args.seed} "
        f"--max-steps {solver.max_steps} --rho0 {solver.rho0:g} --max-slots {solver.max_slots} "
        f"--slot-fraction {solver.slot_fraction:g} --chunk {args.chunk} --repeat-to {args.repeat_to} "
        f"{'--one-device' if args.one_device else ''}"
        f"    [load {', '.join(f'{x:.2f}' for x in os.getloadavg())}]")
    runs: list = []
    counting_queue(runs, solver.max_steps)
    grasps = make_grasps(args.count, args.seed)
    if args.repeat_to:
        grasps = (grasps * -(-args.repeat_to // args.count))[: args.repeat_to]
    res = jaxgrasp.evaluate_batch(grasps, chunk_size=args.chunk, devices=devices,
                                  options=jaxgrasp.EvaluateOptions(solver=solver))
    if args.save:
        import numpy as np

        np.savez(args.save, status=np.asarray(res.status), value=np.asarray(res.value))
    for r in runs:
        share = r[2] / max(r[0] * r[1], 1)
        say(f"   queue run: {r[0]} loop steps x {r[1]} slots, idle slot-steps {r[2]} ({share:.3f})")
    steps = sum(r[0] for r in runs)
    slots = sum(r[0] * r[1] for r in runs)
    idle = sum(r[2] for r in runs)
    status = {name: int((res.status_names == name).sum()) for name in sorted(set(res.status_names))}
    say(f"{len(runs)} queue runs: {steps} loop steps, {slots} slot-steps, idle {idle} ({idle / slots:.3f}); "
        f"statuses {status}")


if __name__ == "__main__":
    main()
