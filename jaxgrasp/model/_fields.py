"""The one table of grasp fields: name, SI unit, shape, allowed range, default, labels.

Everything that names a grasp field is built from `FIELDS`: the [`Grasp`][jaxgrasp.Grasp]
docstring's units, input validation, grasp files, sweep axes, tuning parameters, CLI
options and plot labels. Add or change a field here, not in those places.

Shapes (``N`` contacts):

* ``"points"``: ``(N, 3)`` positions in the object frame;
* ``"directions"``: ``(N, 3)`` vectors in the object frame (normalised by validation);
* ``"per_contact"``: ``(N,)`` one value per contact (a scalar is broadcast);
* ``"scalar"``: ``()`` one value for the grasp;
* ``"vector"``: ``(3,)`` one vector for the grasp, object frame.
"""

from __future__ import annotations

import dataclasses
from typing import Any

__all__ = [
    "Field",
    "FIELDS",
    "FIELD",
    "NAMES",
    "PER_CONTACT",
    "FINGERTIP",
    "SWEEPABLE",
    "TUNABLE",
    "DEFAULT_GRAVITY",
    "DEFAULT_MASS",
    "STANDARD_GRAVITY",
    "MAX_CONTACTS",
]

DEFAULT_GRAVITY = (0.0, 0.0, -9.81)
"""Default gravity vector, m/s^2, object frame (standard gravity along ``-z``)."""

DEFAULT_MASS = 0.0
"""Default object mass, kg."""

STANDARD_GRAVITY = DEFAULT_GRAVITY
"""Default gravity vector, m/s^2, object frame: ``(0, 0, -9.81)``, standard gravity along ``-z``
(the ``gravity`` default of `jaxgrasp.model.FIELDS`)."""


MAX_CONTACTS = 32
"""The most contacts ``N`` one grasp may have (`jaxgrasp.model._validation.check_grasp_inputs`
refuses more, so a grasp file, a dataset row and ``Grasp.create`` all do). The paper's grasps
have 2 to 8 fingertips; a five-fingered hand touching with its fingertips, phalanges and palm
has about 16 contacts; 32 leaves twice that. The evaluation of one grasp solves ``2 N``
boundary problems of ``N`` contacts each, a time that grows more than as ``N^2``
(``experiments/limits/FINDINGS.md``: 32 contacts take seconds, 64 over a minute, 300 tens of
minutes or more), and a batch pads every grasp to its largest count, so one row of hundreds
of contacts would hold up the whole batch. The check also comes before the pairwise distance check,
whose memory grows as ``N^2`` (about 24 GB at 30,000 contacts)."""


@dataclasses.dataclass(frozen=True)
class Field:
    """One grasp field.

    Attributes:
        name: the [`Grasp`][jaxgrasp.Grasp] attribute (and sweep/tune/npz name).
        unit: SI unit, ``""`` for dimensionless.
        shape: ``"points"``, ``"directions"``, ``"per_contact"``, ``"scalar"`` or ``"vector"``.
        minimum: lower bound of the allowed range, ``None`` for none (every value must be
            finite in any case).
        minimum_allowed: whether ``minimum`` itself is allowed (``mass = 0``: yes).
        default: value when not given, ``None`` where the field is required.
        description: what the field is, a short noun phrase (help texts, file comments).
        file_key: key of the field in grasp files (``position`` for ``positions``).
        file_section: where files give it: ``"contacts"`` (per contact), ``"fingertip"``
            (a default for every contact, may be overridden per contact) or ``"object"``.
        symbol: symbol in plots (``"E"``, ``"Δr"``).
        display: ``(factor, unit)`` shown in plots: value in SI times ``factor``.
    """

    name: str
    unit: str
    shape: str
    minimum: float | None
    minimum_allowed: bool
    default: Any
    description: str
    file_key: str
    file_section: str
    symbol: str
    display: tuple[float, str]

    @property
    def per_contact(self) -> bool:
        """One entry per contact (``(N, ...)`` arrays)."""
        return self.shape in ("points", "directions", "per_contact")

    @property
    def ndim(self) -> int:
        """Axes of the field of one grasp: ``(N, 3)`` 2, ``(N,)`` 1, ``()`` 0, ``(3,)`` 1;
        an array with more has batch axes in front."""
        return {"points": 2, "directions": 2, "per_contact": 1, "scalar": 0, "vector": 1}[self.shape]

    @property
    def option(self) -> str:
        """The command-line option that sets it: ``--young-modulus``."""
        return "--" + self.name.replace("_", "-")

    @property
    def metavar(self) -> str | None:
        """Metavar of a CLI option that takes one value: the unit in capitals, or ``None``."""
        return self.unit.upper() or None

    @property
    def column(self) -> str:
        """CSV column name with the unit: ``young_modulus_Pa``, ``friction``."""
        return f"{self.name}_{self.unit}" if self.unit else self.name

    @property
    def rule(self) -> str:
        """The range rule in words, for error messages: ``positive``, ``>= 0``."""
        if self.minimum is None:
            return "finite"
        if self.minimum == 0.0:
            return ">= 0" if self.minimum_allowed else "positive"
        return f">= {self.minimum:g}" if self.minimum_allowed else f"> {self.minimum:g}"

    def allows(self, x) -> Any:
        """Elementwise: is ``x`` (a NumPy array) above the minimum? (``True`` without one.)"""
        if self.minimum is None:
            return x == x
        return x >= self.minimum if self.minimum_allowed else x > self.minimum

    @property
    def comment(self) -> str:
        """The comment beside the field in a written grasp file."""
        if not self.unit:
            return self.description
        return f"{self.unit}, object frame" if self.shape in ("points", "vector") else self.unit

    @property
    def help(self) -> str:
        """Help text of its CLI option: ``Young's modulus of every fingertip, Pa``."""
        text = self.description
        if self.per_contact and "fingertip" not in text:
            text += " of every fingertip"
        return f"{text}, {self.unit}" if self.unit else text

    @property
    def label(self) -> str:
        """Plot axis label with the display unit: ``Young's modulus E [kPa]``."""
        unit = self.display[1]
        return f"{self.description} {self.symbol} [{unit}]" if unit else f"{self.description} {self.symbol}"


def _field(name, unit, shape, minimum, default, description, file_key, file_section, symbol,
           display=None, minimum_allowed=False) -> Field:
    return Field(name, unit, shape, minimum, minimum_allowed, default, description, file_key,
                 file_section, symbol, display or (1.0, unit))


FIELDS: tuple[Field, ...] = (
    _field("positions", "m", "points", None, None, "contact position", "position", "contacts", "p",
           (1e3, "mm")),
    _field("normals", "", "directions", None, None, "outward surface normal", "normal", "contacts", "n"),
    # also < radius, checked with the radius (_validation._check_deformation)
    _field("initial_deformation", "m", "per_contact", 0.0, None, "initial deformation",
           "initial_deformation", "contacts", "Δr", (1e3, "mm")),
    _field("radius", "m", "per_contact", 0.0, None, "fingertip radius", "radius", "fingertip", "r",
           (1e3, "mm")),
    _field("young_modulus", "Pa", "per_contact", 0.0, None, "Young's modulus", "young_modulus",
           "fingertip", "E", (1e-3, "kPa")),
    _field("friction", "", "per_contact", 0.0, None, "static friction coefficient", "friction",
           "fingertip", "μ"),
    _field("max_force", "N", "per_contact", 0.0, None, "normal force limit", "max_force", "fingertip",
           "f_max"),
    _field("mass", "kg", "scalar", 0.0, DEFAULT_MASS, "object mass", "mass", "object", "m",
           minimum_allowed=True),
    _field("gravity", "m/s^2", "vector", None, DEFAULT_GRAVITY, "gravitational acceleration", "gravity",
           "object", "g"),
)
"""Every [`Grasp`][jaxgrasp.Grasp] field, in the grasp's field order."""

FIELD: dict[str, Field] = {f.name: f for f in FIELDS}
"""The fields by name."""

NAMES: tuple[str, ...] = tuple(f.name for f in FIELDS)
"""Field names in the grasp's order."""

PER_CONTACT: tuple[str, ...] = tuple(f.name for f in FIELDS if f.shape == "per_contact")
"""Fields with one number per contact (a scalar is broadcast to every contact)."""

FINGERTIP: tuple[str, ...] = tuple(f.name for f in FIELDS if f.file_section == "fingertip")
"""Fields a grasp file may give once for every fingertip (``[fingertip]``)."""

SWEEPABLE: tuple[str, ...] = ("young_modulus", "initial_deformation", "mass", "friction", "max_force", "radius")
"""Fields a sweep can vary (the paper's two axes first); per-contact ones are set at every
contact at once."""

TUNABLE: tuple[str, ...] = ("initial_deformation", "young_modulus", "friction", "max_force", "radius",
                            "positions", "mass")
"""Fields [`jaxgrasp.tune`][jaxgrasp.tune] can optimise (positions: each contact within its face)."""
