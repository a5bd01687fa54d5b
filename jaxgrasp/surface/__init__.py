"""Object surfaces in JAX: closest points, normals and the rules a fingertip contact on a mesh keeps.

:class:`Surface` is a triangle mesh as arrays (``jit``, ``vmap`` and ``grad`` pass through
it); :meth:`Surface.closest` puts points on the surface with the outward normal of the face
there (:class:`SurfacePoint`). :func:`check_contacts` checks contacts against the rules that
make the paper's planar-contact model apply (:class:`ContactRules`, :class:`RuleCheck`).
"""

from jaxgrasp.surface._rules import (
    ContactRules,
    RuleCheck,
    check_contacts,
    contact_radius,
    deformation_range,
    fingertip_centers,
)
from jaxgrasp.surface._surface import PAD_FACES, Surface, SurfacePoint, closest_on_triangles

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
]
