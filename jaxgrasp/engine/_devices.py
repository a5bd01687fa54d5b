"""One JAX CPU device per core, so that batches and sweeps run on every core.

XLA runs one compiled executable on one CPU device, and jaxgrasp's solver loop is a long
chain of small operations that keeps one core busy. [`jaxgrasp.evaluate_batch`][jaxgrasp.evaluate_batch] and
[`jaxgrasp.sweep`][jaxgrasp.sweep] split each chunk over all devices, each device running its own
work queue (`jaxgrasp.engine._evaluator.over_devices`), so on the CPU they use as many
cores as JAX has CPU devices, and JAX creates one unless told otherwise.

So jaxgrasp asks JAX for one CPU device per core this process may run on
(``jax_num_cpu_devices``) at its first use, or when the program calls
[`jaxgrasp.configure`][jaxgrasp.configure] (`jaxgrasp.engine._setup`): a batch then runs on every
core instead of one. A single [`jaxgrasp.evaluate`][jaxgrasp.evaluate] and the user's own ``jit`` run
on the first device as before.

It is left alone where the choice is the user's or can no longer be made:

* the environment variable ``JAXGRASP_CPU_DEVICES`` (`ENV_VAR`) sets the number
  (``1``: JAX's own single device);
* ``JAX_NUM_CPU_DEVICES``, ``jax.config.update("jax_num_cpu_devices", n)`` before the
  import, or ``--xla_force_host_platform_device_count`` in ``XLA_FLAGS`` are kept;
* JAX has already started its backends (some JAX computation ran before jaxgrasp's
  first use, such as making a preset grasp): JAX's devices stay as they are.
"""

from __future__ import annotations

import os

import jax

__all__ = ["ENV_VAR", "usable_cores", "requested_cpu_devices", "user_chose", "configure_cpu_devices"]

ENV_VAR = "JAXGRASP_CPU_DEVICES"
"""The environment variable that sets the number of CPU devices (a positive integer;
``1``: JAX's own single device)."""


def usable_cores() -> int:
    """The CPU cores this process may run on (its affinity mask where the OS has one)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - macOS, Windows
        return max(1, os.cpu_count() or 1)


def requested_cpu_devices(environ=os.environ) -> int:
    """``$JAXGRASP_CPU_DEVICES`` as a positive integer, else `usable_cores`.

    Raises:
        ValueError: one line, if the variable is set to anything but a positive integer.
    """
    text = environ.get(ENV_VAR)
    if text is None:
        return usable_cores()
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise ValueError(f"{ENV_VAR} must be a positive integer (CPU devices), got {text!r}")
    return n


def user_chose(environ=os.environ) -> bool:
    """Whether the CPU device count is already the user's choice (JAX's own settings)."""
    return (
        "JAX_NUM_CPU_DEVICES" in environ
        or jax.config.jax_num_cpu_devices != -1
        or "xla_force_host_platform_device_count" in environ.get("XLA_FLAGS", "")
    )


def configure_cpu_devices(environ=os.environ) -> int | None:
    """Ask JAX for `requested_cpu_devices` CPU devices; the number set, or ``None``
    where it is left alone (see the module docstring). Called by [`jaxgrasp.configure`][jaxgrasp.configure]."""
    explicit = ENV_VAR in environ
    n = requested_cpu_devices(environ)  # a bad value fails even where it would not be used
    if not explicit and user_chose(environ):
        return None
    try:
        jax.config.update("jax_num_cpu_devices", n)
    except RuntimeError:  # JAX's backends are running already: its devices stay
        return None
    return n
