#!/usr/bin/env python3
"""Generates the small committed test meshes in this folder (see README.md).

Run from this folder:  python3 make_meshes.py   (needs `pip install vtk numpy`).
The Rust tests do not run Python: they read the committed outputs and compare them with the
same analytic truth (points of `mixed_points()`, fields `temperature = x + 2y + 3z`,
`pressure = x*y - z`, `id = point index`).
"""
import os
import numpy as np
try:  # make_gmsh.py imports this module under Debian's Python, which has no vtk
    import vtk
    from vtk.util import numpy_support as ns
except ImportError:
    vtk = None


def mixed_points():
    pts = []
    for k in range(2):
        for j in range(3):
            for i in range(3):
                pts.append((0.5 * i, 0.25 * j, 1.0 * k))
    pts.append((0.25, 0.125, 1.5))  # 18: pyramid apex
    pts.append((0.5, 0.0, 1.5))     # 19..21: wedge top
    pts.append((1.0, 0.0, 1.5))
    pts.append((1.0, 0.25, 1.5))
    pts.append((0.1, 0.4, 1.6))     # 22: tet apex
    return np.array(pts, dtype=np.float64)


def g(i, j, k):
    return i + 3 * j + 9 * k


# (vtk cell type, connectivity) in VTK vertex order.
def mixed_cells():
    cells = []
    for j in range(2):
        for i in range(2):
            cells.append((12, [g(i, j, 0), g(i + 1, j, 0), g(i + 1, j + 1, 0), g(i, j + 1, 0),
                               g(i, j, 1), g(i + 1, j, 1), g(i + 1, j + 1, 1), g(i, j + 1, 1)]))
    cells.append((14, [g(0, 0, 1), g(1, 0, 1), g(1, 1, 1), g(0, 1, 1), 18]))       # pyramid
    cells.append((13, [g(1, 0, 1), g(2, 0, 1), g(2, 1, 1), 19, 20, 21]))         # wedge
    cells.append((10, [g(0, 1, 1), g(1, 1, 1), g(0, 2, 1), 22]))                 # tet
    cells.append((5, [0, 1, 3]))                                                 # triangle (skipped)
    cells.append((1, [5]))                                                       # vertex (skipped)
    cells.append((3, [0, 17]))                                                   # line (skipped)
    return cells


def fields(p):
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    return {
        "temperature": x + 2 * y + 3 * z,
        "pressure": x * y - z,
        "id": np.arange(len(p), dtype=np.int32),
    }


def vtk_grid(point_type):
    p = mixed_points()
    grid = vtk.vtkUnstructuredGrid()
    pts = vtk.vtkPoints()
    pts.SetDataType(point_type)
    for q in p:
        pts.InsertNextPoint(*q)
    grid.SetPoints(pts)
    for ctype, conn in mixed_cells():
        ids = vtk.vtkIdList()
        for c in conn:
            ids.InsertNextId(c)
        grid.InsertNextCell(ctype, ids)
    f = fields(p)
    t = ns.numpy_to_vtk(f["temperature"].astype(np.float64), deep=True)
    t.SetName("temperature")
    grid.GetPointData().SetScalars(t)
    pr = ns.numpy_to_vtk(f["pressure"].astype(np.float32), deep=True)
    pr.SetName("pressure")
    grid.GetPointData().AddArray(pr)
    i = ns.numpy_to_vtk(f["id"], deep=True)
    i.SetName("id")
    grid.GetPointData().AddArray(i)
    v = ns.numpy_to_vtk(np.ascontiguousarray(p.astype(np.float32)), deep=True)
    v.SetName("velocity")  # 3 components: listed as skipped, not a scalar field
    grid.GetPointData().AddArray(v)
    return grid


def write_legacy(name, grid, binary, version):
    w = vtk.vtkUnstructuredGridWriter()
    w.SetFileName(name)
    w.SetInputData(grid)
    if binary:
        w.SetFileTypeToBinary()
    else:
        w.SetFileTypeToASCII()
    if version == 42:
        w.SetFileVersion(42)
    w.Write()


def write_vtu(name, grid, mode, compress, header64, encode=True):
    w = vtk.vtkXMLUnstructuredGridWriter()
    w.SetFileName(name)
    w.SetInputData(grid)
    {"ascii": w.SetDataModeToAscii, "binary": w.SetDataModeToBinary,
     "appended": w.SetDataModeToAppended}[mode]()
    if compress:
        w.SetCompressorTypeToZLib()
        w.SetBlockSize(256)  # several blocks even for this small mesh
    else:
        w.SetCompressorTypeToNone()
    if header64:
        w.SetHeaderTypeToUInt64()
    else:
        w.SetHeaderTypeToUInt32()
    w.SetEncodeAppendedData(1 if encode else 0)
    w.Write()


def main():
    g32 = vtk_grid(vtk.VTK_FLOAT)
    g64 = vtk_grid(vtk.VTK_DOUBLE)
    # Legacy VTK: 4.2 and 5.1, ascii and binary (big-endian), f32 and f64 points.
    write_legacy("mixed_v42_ascii.vtk", g64, False, 42)
    write_legacy("mixed_v42_binary.vtk", g32, True, 42)
    write_legacy("mixed_v51_ascii.vtk", g32, False, 51)
    write_legacy("mixed_v51_binary.vtk", g64, True, 51)
    # VTK XML.
    write_vtu("mixed_ascii.vtu", g64, "ascii", False, False)
    write_vtu("mixed_base64.vtu", g32, "binary", False, False)
    write_vtu("mixed_base64_zlib.vtu", g64, "binary", True, False)
    write_vtu("mixed_base64_zlib_u64.vtu", g32, "binary", True, True)
    write_vtu("mixed_appended_raw.vtu", g64, "appended", False, False, encode=False)
    write_vtu("mixed_appended_raw_zlib_u64.vtu", g32, "appended", True, True, encode=False)
    write_vtu("mixed_appended_base64.vtu", g32, "appended", False, True, encode=True)
    write_vtu("mixed_appended_base64_zlib.vtu", g64, "appended", True, False, encode=True)

    # Gmsh files: see make_gmsh.py (written by Gmsh itself).

    # Time series: 3 steps of the mixed mesh, points moving and field changing; a .pvd.
    steps = []
    for s in range(3):
        q = mixed_points() + np.array([0.1 * s, 0.0, 0.0])
        gs = vtk_grid(vtk.VTK_DOUBLE)
        pts = vtk.vtkPoints()
        pts.SetDataType(vtk.VTK_DOUBLE)
        for r in q:
            pts.InsertNextPoint(*r)
        gs.SetPoints(pts)
        tt = ns.numpy_to_vtk(q[:, 0] + 2 * q[:, 1] + 3 * q[:, 2] + s, deep=True)
        tt.SetName("temperature")
        gs.GetPointData().SetScalars(tt)
        os.makedirs("series", exist_ok=True)
        name = f"series/step_{s:03d}.vtu"
        write_vtu(name, gs, "appended", True, False, encode=False)
        steps.append((0.5 * s, name))
    with open("series.pvd", "w") as fh:
        fh.write('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n')
        for t, name in steps:
            fh.write(f'    <DataSet timestep="{t}" group="" part="0" file="{name}"/>\n')
        fh.write('  </Collection>\n</VTKFile>\n')


if __name__ == "__main__":
    main()
