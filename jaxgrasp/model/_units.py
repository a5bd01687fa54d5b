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

# Lengths no grasp of soft fingertips reaches: past them the numbers were written in
# millimetres (or a mesh's vertices read in the wrong unit), and the model, which takes
# them as metres, would answer for a giant (a fingertip of 25 m: 'infeasible, force margin
# -0.998', no word about units). Each is far above every real case and far below the same
# case in mm, so the two never meet: validation and mesh loading name the mistake instead.

MAX_FINGERTIP_RADIUS = 1.0
"""Largest fingertip radius, m. Soft fingertips are millimetres to centimetres (the paper's
25 mm; robot finger pads up to a few cm): one metre is forty times the paper's, while the
same fingertips in mm are 5 to 50 "m". A radius of more than 1 mm written in mm is caught
(the deformation is below the radius, so it is caught with it)."""

MAX_CONTACT_DISTANCE = 10.0
"""Farthest a contact may be from the centre of mass, m. Fingers grasp objects up to a
metre or two across; a contact 10 m away belongs to an object 20 m across, while positions
written in mm are tens to hundreds of "m" for any object more than 20 mm across. A mesh
within `MAX_OBJECT_SIZE` has every surface point within ``sqrt(3) * 5 = 8.7`` m of a
centre of mass inside its box, so a grasp on a mesh that loads never breaks this."""

MAX_OBJECT_SIZE = 5.0
"""Largest extent of a grasped object's mesh along an axis (of its bounding box), m, after
its ``units``. Hands hold objects up to a metre or two (a box carried in both arms); a
mesh of more than 5 m is one whose vertices are in mm (or cm) read as metres: the usual
CAD or scan of a 100 mm part becomes a 100 m object, a billion times too heavy."""
