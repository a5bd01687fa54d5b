"""Conversion between SI units (the library's interface) and the internal unit system.

The solver works in millimetres, newtons, N/mm^2 (= MPa) and millijoules (N mm): in
these units a typical deformation is ~1, a typical energy ~1, and float64 (or even
float32) keeps its digits. Every public function takes and returns SI units.
"""

M_TO_MM = 1.0e3
"""Length: metres to millimetres."""
PA_TO_MPA = 1.0e-6
"""Young's modulus: Pa (N/m^2) to N/mm^2."""
MJ_TO_J = 1.0e-3
"""Energy: millijoules (N mm) to joules."""

LENGTH_UNITS = {"m": 1.0, "cm": 1.0e-2, "mm": 1.0e-3}
"""Length units a mesh's vertices may be given in, and each one's size in metres
([`jaxgrasp.from_mesh`][jaxgrasp.from_mesh], the ``units`` key of a grasp file's ``[object]``)."""
