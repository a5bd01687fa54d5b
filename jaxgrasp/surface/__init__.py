"""Object surfaces in JAX: closest points, normals and the rules a fingertip contact on a mesh keeps.

[`Surface`][jaxgrasp.surface.Surface] is a triangle mesh as arrays (``jit``, ``vmap`` and ``grad`` pass through
it); [`Surface.closest`][jaxgrasp.surface.Surface.closest] puts points on the surface with the outward normal of the face
there (`SurfacePoint`). [`check_contacts`][jaxgrasp.surface.check_contacts] checks contacts against the rules that
make the paper's planar-contact model apply ([`ContactRules`][jaxgrasp.surface.ContactRules], [`RuleCheck`][jaxgrasp.surface.RuleCheck]).
A grasp on a mesh is a [`MeshGrasp`][jaxgrasp.MeshGrasp]: its contacts snapped to the surface, the centre
of mass and the frame ([`jaxgrasp.from_mesh`][jaxgrasp.from_mesh] reads a mesh file and builds one).
`closest_on_triangles` is the one closest-point rule, in JAX (traced) or NumPy; a
bounding volume hierarchy over the faces, built once per surface, finds the faces it is
run on, so a search costs about the logarithm of the face count and memory never grows
with the queries times the faces.

``__all__`` lists the names promised to users; the names imported below it are for
jaxgrasp's other packages, not promised (the faces' convention: ``docs/development.md``,
"Layout").
"""

from typing import TYPE_CHECKING

from jaxgrasp import _startup

if TYPE_CHECKING:  # read by _startup.attach (below): each name is loaded from its module when first used
    from jaxgrasp.surface._mesh import MeshGrasp
    from jaxgrasp.surface._rules import (
        ContactRules,
        RuleCheck,
        check_contacts,
        contact_radius,
        deformation_range,
        fingertip_centers,
    )
    from jaxgrasp.surface._surface import PAD_FACES, Surface, SurfacePoint
    from jaxgrasp.surface._triangles import closest_on_triangles

    # For jaxgrasp's other packages: not in __all__, not promised to users (see the docstring).
    from jaxgrasp.surface._grid import GRID_POINTS_PER_AXIS, DistanceGrid, distance_grid
    from jaxgrasp.surface._mesh import DEFAULT_TOLERANCE, grasp_on_mesh, mass_properties
    from jaxgrasp.surface._tree import FaceTree, build_tree, first_hits, nearest_faces

__all__ = [
    "Surface",
    "SurfacePoint",
    "closest_on_triangles",
    "PAD_FACES",
    "ContactRules",
    "RuleCheck",
    "check_contacts",
    "contact_radius",
    "deformation_range",
    "fingertip_centers",
    "MeshGrasp",
]

__getattr__, __dir__, _LAZY = _startup.attach(__name__)
