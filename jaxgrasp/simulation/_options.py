"""The options of [`simulate`][jaxgrasp.simulate], checked in one place before any evaluation.

`check_options` is what ``jaxgrasp.simulate`` and ``jaxgrasp simulate`` both call
before they evaluate the grasp; its one-line [`GraspValueError`][jaxgrasp.GraspValueError] names each
option as ``names`` spells it (the command passes its ``--options``). Beyond sign and
finiteness it holds a run to three rules:

* a given timestep is at most `TIMESTEP_FRACTION` (1/100) of the shortest trial
  (hold, six-axis, and kick where kick scales are given), so that every trial is at least
  100 steps;
* the trials add up to at most `MAX_SIMULATED_S` of simulated time: the hold, six
  six-axis trials and ``len(kick_scales) * (random_kicks + 1)`` kicks (one least-energy kick
  per scale counted);
* they take at most `MAX_STEPS` MuJoCo steps, their time / timestep. With the
  automatic timestep the count is known once the scene is built: `check_steps` runs
  then, before any trial;
* every kick scale is at most `MAX_KICK_SCALE`, and once the scene is built (its
  timestep, fingertips and mass known) no kick may carry a contact point more than
  `MAX_KICK_TRAVEL` fingertip radii in one timestep (`check_kick_travel`, before any
  trial): a kick beyond that is beyond what MuJoCo integrates.

The two caps keep one run of a few contacts to minutes on one core, not hours.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from jaxgrasp.model import GraspValueError
from jaxgrasp.simulation._limits import MAX_KICK_SCALE, MAX_KICK_TRAVEL, MAX_SIMULATED_S, MAX_STEPS, TIMESTEP_FRACTION

__all__ = ["DEFAULTS", "check_kick_travel", "check_number", "check_options", "check_steps", "simulated_time"]

DEFAULTS = {
    "hold_time_s": 1.0,
    "hold_tolerance_m": 1e-3,
    "hold_tolerance_rad": math.radians(1.0),
    "six_axis_time_s": 2.0,
    "disturbance_acceleration_m_s2": 10.0,
    "six_axis_tolerance_m": 0.05,
    "six_axis_tolerance_rad": math.radians(15.0),
    "kick_time_s": 0.3,
    "sample_s": 0.005,
}
"""The default durations and tolerances of the trials (SI units)."""


def check_number(name: str, value, lo: float = 0.0, strict: bool = True) -> float:
    """``value`` as a finite float above ``lo`` (``strict``) or at least ``lo``; a one-line
    [`GraspValueError`][jaxgrasp.GraspValueError] naming ``name`` otherwise."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise GraspValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(x) or (x <= lo if strict else x < lo):
        raise GraspValueError(f"{name} must be finite and {'>' if strict else '>='} {lo:g}, got {x:g}")
    return x


def check_options(*, kick_scales, random_kicks, friction=None, timestep=None, nominal_mass=None,
                  damping_ratio=None, names: Mapping[str, str] | None = None, **durations) -> dict:
    """[`simulate`][jaxgrasp.simulate]'s options, checked, as the dict it runs on.

    ``friction`` and ``timestep`` ``None``: the grasp's and the automatic one;
    ``nominal_mass`` and ``damping_ratio`` ``None``: not given (not in the result);
    ``durations``: any of `DEFAULTS`, the others their defaults. ``names`` maps a
    parameter (``hold_time_s``) to the name messages use (``--hold-time``).

    Raises:
        GraspValueError: one line naming the first bad option (module doc: the rules).
    """
    label = (lambda k: names.get(k, k)) if names else (lambda k: k)
    unknown = sorted(set(durations) - set(DEFAULTS))
    if unknown:
        raise GraspValueError(f"unknown option {unknown[0]!r}; the trial options are {', '.join(DEFAULTS)}")
    opts = {k: check_number(label(k), durations.get(k, v)) for k, v in DEFAULTS.items()}
    opts["friction"] = None if friction is None else check_number(label("friction"), friction)
    if nominal_mass is not None:
        opts["nominal_mass_kg"] = check_number(label("nominal_mass"), nominal_mass)
    if damping_ratio is not None:
        opts["damping_ratio"] = check_number(label("damping_ratio"), damping_ratio, strict=False)
    opts["timestep"] = None if timestep is None else check_number(label("timestep"), timestep)
    opts["kick_scales"] = [_check_scale(label("kick_scales"), s) for s in kick_scales]
    if isinstance(random_kicks, bool) or not isinstance(random_kicks, (int, np.integer)) or random_kicks < 0:
        raise GraspValueError(f"{label('random_kicks')} must be an integer >= 0, got {random_kicks!r}")
    opts["random_kicks"] = int(random_kicks)
    _check_timestep(opts, label)
    _check_simulated_time(opts, label)
    if opts["timestep"] is not None:
        check_steps(opts, opts["timestep"], label)
    return opts


def _check_scale(name: str, value) -> float:
    """A kick scale: finite, ``>= 0`` and at most `MAX_KICK_SCALE`."""
    s = check_number(name, value, strict=False)
    if s > MAX_KICK_SCALE:
        raise GraspValueError(
            f"{name} {s:g} is too large: a kick of {s:g} times the value is beyond what the simulator "
            f"integrates; at most {MAX_KICK_SCALE:g}")
    return s


def _trial_times(opts, label) -> list[tuple[str, float]]:
    """``(name, s)`` of each kind of trial the run has (kicks only where scales are given)."""
    kinds = ["hold_time_s", "six_axis_time_s"] + (["kick_time_s"] if opts["kick_scales"] else [])
    return [(label(k), opts[k]) for k in kinds]


def _check_timestep(opts, label) -> None:
    dt = opts["timestep"]
    if dt is None:
        return
    name, shortest = min(_trial_times(opts, label), key=lambda kv: kv[1])
    if dt > TIMESTEP_FRACTION * shortest:
        raise GraspValueError(
            f"{label('timestep')} {dt:g} s is too long: at most 1/{round(1 / TIMESTEP_FRACTION)} of the shortest "
            f"trial ({name} {shortest:g} s), {TIMESTEP_FRACTION * shortest:g} s")


def _kicks(opts) -> int:
    return len(opts["kick_scales"]) * (opts["random_kicks"] + 1)


def simulated_time(opts) -> float:
    """The simulated time of all trials, s (every kick counted)."""
    return opts["hold_time_s"] + 6 * opts["six_axis_time_s"] + _kicks(opts) * opts["kick_time_s"]


def _check_simulated_time(opts, label) -> None:
    total = simulated_time(opts)
    if total > MAX_SIMULATED_S:
        raise GraspValueError(
            f"the trials add up to {total:g} s of simulated time ({label('hold_time_s')} {opts['hold_time_s']:g}"
            f" + 6 x {label('six_axis_time_s')} {opts['six_axis_time_s']:g} + {_kicks(opts)} kicks x "
            f"{label('kick_time_s')} {opts['kick_time_s']:g}); at most {MAX_SIMULATED_S:g} s: shorten them")


def check_steps(opts, timestep: float, label=None) -> None:
    """At most `MAX_STEPS` steps of ``timestep`` s for the trials of ``opts`` (the
    checked options; ``opts["timestep"]`` ``None``: ``timestep`` is the automatic one)."""
    label = label or (lambda k: k)
    total = simulated_time(opts)
    steps = total / timestep
    if steps > MAX_STEPS:
        given = (f"{label('timestep')} {timestep:g} s" if opts["timestep"] is not None
                 else f"the automatic timestep {timestep:g} s, from the contact stiffness")
        raise GraspValueError(
            f"the trials need {steps:.3g} MuJoCo steps ({total:g} s at {given}); at most {MAX_STEPS:,}: "
            f"shorten the trials or give a longer {label('timestep')}")


def check_kick_travel(kicks, timestep: float, radius: float, reach: float) -> None:
    """Refuse a kick that moves a contact point more than `MAX_KICK_TRAVEL` fingertip
    radii in one timestep: beyond what MuJoCo integrates (`_limits.MAX_KICK_TRAVEL`).

    Args:
        kicks: ``(scale, velocity)`` pairs, ``velocity`` ``(6,)`` the object's initial
            linear (m/s) and angular (rad/s) velocity.
        timestep: s.
        radius: the smallest fingertip radius, m.
        reach: the contacts' largest distance from the centre of mass, m.

    Raises:
        GraspValueError: one line naming the first such scale, its travel per step, the
            limit and the largest scale that stays within it.
    """
    limit = MAX_KICK_TRAVEL * radius
    for s, v in kicks:
        v = np.asarray(v, dtype=np.float64)
        speed = float(np.linalg.norm(v[:3]) + np.linalg.norm(v[3:]) * reach)  # m/s, the fastest contact point
        travel = speed * timestep
        if not travel <= limit:  # NaN too
            largest = s * (limit / travel) ** 2 if travel > 0 and math.isfinite(travel) else 0.0
            raise GraspValueError(
                f"a kick of {s:g} times the value moves the contacts {travel:.3g} m in one timestep of "
                f"{timestep:.3g} s ({speed:.3g} m/s); MuJoCo integrates at most {MAX_KICK_TRAVEL:g} fingertip "
                f"radius ({limit:.3g} m) per step: use scales up to {largest:.3g} for this grasp")
