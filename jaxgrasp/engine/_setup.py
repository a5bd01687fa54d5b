"""jaxgrasp's process-wide settings beyond float64, chosen at its first use or by [`configure`][jaxgrasp.configure].

``import jaxgrasp`` turns on float64 and changes nothing else in the process
(`jaxgrasp`). What the engine needs of the process is chosen once, by
[`configure`][jaxgrasp.configure], which the engine calls itself (`first_use`) the first time it
plans a batch or builds a compiled executable, unless the program called it before:

* the number of JAX CPU devices (`jaxgrasp.engine._devices.configure_cpu_devices`):
  one per core, or ``JAXGRASP_CPU_DEVICES``, unless the program chose with JAX's own
  settings. JAX fixes its devices when it makes its first array, which a script usually
  does before jaxgrasp's first batch (a preset grasp is made of JAX arrays): there JAX's
  devices stay, a batch runs on them, and the batch's first use says so once on the
  ``"jaxgrasp"`` logger. Call [`configure`][jaxgrasp.configure] before the first JAX computation to give
  batches every core.
* the executable store in the user's cache folder
  (`jaxgrasp.engine._store.enable_from_environment`; ``JAXGRASP_CACHE_DIR`` moves or
  switches it off): the first compilation writes there, nothing before.
* jaxgrasp's messages on stderr where the program has configured no logging
  (`jaxgrasp.engine._progress.show_by_default`).

The guide's page on caching and process-wide settings (``docs/guide/caching.md``) lists
them for users.
"""

from __future__ import annotations

import os
import threading

import jax

from jaxgrasp.engine import _devices, _progress, _store

__all__ = ["configure", "first_use"]

_LOCK = threading.Lock()
_DONE: dict | None = None
"""What [`configure`][jaxgrasp.configure] chose (its return value), once it has run."""
_LATE: list[int] = []
"""The CPU devices asked for where JAX's devices were already made (at most one entry)."""


def configure(*, cpu_devices: int | None = None) -> dict:
    """Choose jaxgrasp's process-wide settings now, instead of at its first use.

    Call it before the program's first JAX computation (the first array) for its device
    count to count. Where it is not called, jaxgrasp's first batch or compilation calls
    it without arguments.

    Args:
        cpu_devices: the number of JAX CPU devices that batches and sweeps are split over
            (default ``$JAXGRASP_CPU_DEVICES``, else one per usable core; JAX's own
            settings ``JAX_NUM_CPU_DEVICES``, ``jax_num_cpu_devices`` or
            ``--xla_force_host_platform_device_count`` are kept where no number is given).
            Where JAX has already made its devices they stay as they are.

    Returns:
        ``{"cpu_devices": n or None, "executable_store": folder or None}``: the CPU devices
        set here (``None``: JAX's devices or the user's choice stay), and the folder of the
        executable store (``None``: switched off, refused or not creatable).

    Raises:
        ValueError: one line, for a ``cpu_devices`` (or ``JAXGRASP_CPU_DEVICES``) that is
            not a positive integer.
    """
    global _DONE
    with _LOCK:
        env = dict(os.environ)
        if cpu_devices is not None:
            env[_devices.ENV_VAR] = str(cpu_devices)
        wanted = _devices.requested_cpu_devices(env)  # a bad value fails here, in one line
        n = _devices.configure_cpu_devices(env)
        if n is None and not _devices.user_chose() and (_DONE is None or _DONE["cpu_devices"] != wanted):
            _LATE[:] = [wanted]
        chosen, store = _store.chosen_dir()  # a store the program chose stays
        if not chosen:
            store = _store.enable_from_environment()
        _progress.show_by_default()
        _DONE = {"cpu_devices": n if n is not None else (_DONE or {}).get("cpu_devices"),
                 "executable_store": store}
        return dict(_DONE)


def first_use(batch: bool = False) -> None:
    """[`configure`][jaxgrasp.configure] without arguments, if it has not run; ``batch``: a batch is
    planned now, which says once on the ``"jaxgrasp"`` logger where JAX's devices were
    made before jaxgrasp could ask for more (the batch runs on fewer cores)."""
    if _DONE is None:
        configure()
    if batch and _LATE:
        wanted = _LATE.pop()
        have = jax.devices()
        if have[0].platform == "cpu" and len(have) < wanted:
            _progress.LOGGER.info(
                "jaxgrasp: JAX made its devices before jaxgrasp's first use: batches run on %d CPU "
                "device%s, not %d; call jaxgrasp.configure() before the first JAX computation to use %d",
                len(have), "" if len(have) == 1 else "s", wanted, wanted)
