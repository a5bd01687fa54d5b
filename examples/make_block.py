"""Make ``examples/block.stl``: a wooden block with chamfered edges, as a CAD tool would give it.

120 x 60 x 40 mm, every edge chamfered 8 mm, vertices in millimetres, origin at the centre
of the bottom face (so the mesh's origin is NOT the centre of mass, which is 20 mm above
it). ``examples/block.toml`` grasps it; ``jaxgrasp show examples/block.toml`` draws it.

Run from the repository root: ``python examples/make_block.py``.
"""

from pathlib import Path

import numpy as np
import trimesh

SIZE = np.array([120.0, 60.0, 40.0])  # mm
CHAMFER = 8.0  # mm


def chamfered_box(size, chamfer) -> trimesh.Trimesh:
    """The convex hull of each corner moved inward by ``chamfer`` along its three edges."""
    half = np.asarray(size) / 2
    points = []
    for corner in np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).T.reshape(-1, 3):
        for axis in range(3):
            p = corner * half
            p[axis] -= corner[axis] * chamfer
            points.append(p)
    return trimesh.convex.convex_hull(np.array(points))


if __name__ == "__main__":
    block = chamfered_box(SIZE, CHAMFER)
    block.apply_translation([0.0, 0.0, SIZE[2] / 2])  # origin at the bottom face's centre
    out = Path(__file__).with_name("block.stl")
    block.export(out)
    print(f"wrote {out}: {len(block.faces)} faces, watertight {block.is_watertight}, "
          f"volume {block.volume:.0f} mm^3, centre of mass {np.round(block.center_mass, 6)} mm")
