#!/usr/bin/env python3
"""Write the example user mesh ros_ws/src/softkin_fk/examples/finger_mm.msh.

The 3-tendon finger (resolution 1, 1152 tetrahedra) as a researcher's gmsh model would look:
millimetres, the volume as physical group "finger", the base face (x = 0) as physical surface
"base", the tracked corner as physical point "tip" -- and no cables or actuators in the file:
those come from the hand-written spec examples/finger_mm.json (cable polylines).

    ./dev run python scripts/softkin_example_mesh.py [OUT.msh]
"""
import sys

import meshio
import numpy as np

from softkin_fk.core.models import build_tendon_finger


def main(out='ros_ws/src/softkin_fk/examples/finger_mm.msh'):
    m = build_tendon_finger(resolution=1)
    x = m.vertices * 1e3  # file units: mm
    tets = m.group('body').elements
    faces = m.boundary_faces()
    base = faces[np.all(np.abs(x[faces][:, :, 0]) < 1e-9, axis=1)]
    tip = np.array([[m.markers['tip']]])
    cells = [('tetra', tets), ('triangle', base), ('vertex', tip)]
    tags = [np.full(len(tets), 1), np.full(len(base), 2), np.full(1, 3)]
    mesh = meshio.Mesh(x, cells, cell_data={'gmsh:physical': tags, 'gmsh:geometrical': tags},
                       field_data={'finger': np.array([1, 3]), 'base': np.array([2, 2]), 'tip': np.array([3, 0])})
    meshio.write(out, mesh, file_format='gmsh22', binary=False)
    print(f"wrote {out}: {len(x)} vertices, {len(tets)} tetrahedra, {len(base)} base triangles")


if __name__ == '__main__':
    main(*sys.argv[1:])
