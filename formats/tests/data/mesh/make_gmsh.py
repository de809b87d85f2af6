#!/usr/bin/python3
"""Writes the Gmsh test meshes with Gmsh itself (Debian packages `gmsh`, `python3-gmsh`).

Run from this folder with Debian's Python:  /usr/bin/python3 make_gmsh.py
Same mesh and fields as make_meshes.py (mixed_points/mixed_cells/fields), node data as
$NodeData views appended after the mesh. Also meshes a unit box with tetrahedra
(box_msh*.msh): the tests check that the tet volumes sum to 1.
"""
import numpy as np
import gmsh
from make_meshes import mixed_points, mixed_cells, fields

# VTK cell type -> Gmsh element type (first order).
GMSH_TYPE = {10: 4, 12: 5, 13: 6, 14: 7, 5: 2, 3: 1, 1: 15}


def write_mixed():
    p = mixed_points()
    f = fields(p)
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.model.add("mixed")
    gmsh.option.setNumber("PostProcessing.SaveMesh", 0)  # views append only $NodeData
    vol = gmsh.model.addDiscreteEntity(3)
    tags = list(range(1, len(p) + 1))  # Gmsh node tags are 1-based
    gmsh.model.mesh.addNodes(3, vol, tags, p.flatten().tolist())
    # Lower-dimensional cells live on entities of their own dimension.
    ent = {3: vol, 2: gmsh.model.addDiscreteEntity(2), 1: gmsh.model.addDiscreteEntity(1),
           0: gmsh.model.addDiscreteEntity(0)}
    dim = {10: 3, 12: 3, 13: 3, 14: 3, 5: 2, 3: 1, 1: 0}
    etag = 1
    for ctype, conn in mixed_cells():
        gmsh.model.mesh.addElementsByType(ent[dim[ctype]], GMSH_TYPE[ctype], [etag],
                                          [c + 1 for c in conn])
        etag += 1
    views = []
    for name in ("temperature", "pressure"):
        v = gmsh.view.add(name)
        gmsh.view.addModelData(v, 0, "mixed", "NodeData", tags,
                               [[float(x)] for x in f[name]], numComponents=1)
        views.append(v)
    for version in (2.2, 4.1):
        for binary in (0, 1):
            gmsh.option.setNumber("Mesh.MshFileVersion", version)
            gmsh.option.setNumber("Mesh.Binary", binary)
            gmsh.option.setNumber("PostProcessing.Format", 1 if binary else 0)  # 0 ascii, 1 binary
            tag = "22" if version == 2.2 else "41"
            name = f"mixed_msh{tag}_{'binary' if binary else 'ascii'}.msh"
            gmsh.write(name)
            for v in views:
                gmsh.view.write(v, name, append=True)
    gmsh.finalize()


def write_box():
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.model.add("box")
    gmsh.model.occ.addBox(0, 0, 0, 1, 1, 1)
    gmsh.model.occ.synchronize()
    gmsh.option.setNumber("Mesh.MeshSizeMin", 0.6)
    gmsh.option.setNumber("Mesh.MeshSizeMax", 0.6)
    gmsh.model.mesh.generate(3)
    for version in (2.2, 4.1):
        for binary in (0, 1):
            gmsh.option.setNumber("Mesh.MshFileVersion", version)
            gmsh.option.setNumber("Mesh.Binary", binary)
            tag = "22" if version == 2.2 else "41"
            gmsh.write(f"box_msh{tag}_{'binary' if binary else 'ascii'}.msh")
    gmsh.finalize()


if __name__ == "__main__":
    write_mixed()
    write_box()
