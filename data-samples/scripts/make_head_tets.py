#!/usr/bin/env python3
"""A tetrahedral mesh of a real shape with a real field, for the tet benchmarks against Embree
(docs/benchmarks.md, "Against Embree"): the head surface of an MRI volume (VTK Flying Edges
at a low isovalue, smoothed and decimated), filled with tetrahedra by TetGen, and the MRI's
intensity sampled at every tet vertex (VTK probe, trilinear) as the point array "t1".

    python make_head_tets.py MRI.nii.gz OUT.vtu [--skin 40] [--triangles 30000] [--max-volume 30]

Needs vtk, nibabel, numpy and the `tetgen` program (Debian package tetgen). Written files:
OUT.vtu (VTK XML unstructured grid, binary) and OUT.poly beside it (the surface TetGen got)."""
import argparse
import os
import subprocess
import tempfile

import nibabel as nib
import numpy as np
import vtk
from vtk.util import numpy_support as ns


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("mri")
    ap.add_argument("out")
    ap.add_argument("--skin", type=float, default=40.0)
    ap.add_argument("--triangles", type=int, default=30000)
    ap.add_argument("--max-volume", type=float, default=30.0, help="TetGen -a, mm^3")
    a = ap.parse_args()
    img = nib.load(a.mri)
    data = np.asarray(img.dataobj, dtype=np.float32)
    aff = img.affine
    if not np.allclose(aff[:3, :3], np.diag(np.diag(aff[:3, :3]))):
        raise SystemExit("this script expects an axis-aligned affine")
    image = vtk.vtkImageData()
    image.SetDimensions(*data.shape)
    image.SetSpacing(*np.diag(aff[:3, :3]))
    image.SetOrigin(*aff[:3, 3])
    image.GetPointData().SetScalars(ns.numpy_to_vtk(data.ravel(order="F"), deep=True))

    fe = vtk.vtkFlyingEdges3D()
    fe.SetInputData(image)
    fe.SetValue(0, a.skin)
    conn = vtk.vtkPolyDataConnectivityFilter()
    conn.SetInputConnection(fe.GetOutputPort())
    conn.SetExtractionModeToLargestRegion()
    fill = vtk.vtkFillHolesFilter()
    fill.SetInputConnection(conn.GetOutputPort())
    fill.SetHoleSize(1e6)
    smooth = vtk.vtkWindowedSincPolyDataFilter()
    smooth.SetInputConnection(fill.GetOutputPort())
    smooth.SetNumberOfIterations(20)
    tri = vtk.vtkTriangleFilter()
    tri.SetInputConnection(smooth.GetOutputPort())
    tri.Update()
    n0 = tri.GetOutput().GetNumberOfPolys()
    dec = vtk.vtkQuadricDecimation()
    dec.SetInputConnection(tri.GetOutputPort())
    dec.SetTargetReduction(max(0.0, 1.0 - a.triangles / max(n0, 1)))
    clean = vtk.vtkCleanPolyData()
    clean.SetInputConnection(dec.GetOutputPort())
    clean.Update()
    surf = clean.GetOutput()
    pts = ns.vtk_to_numpy(surf.GetPoints().GetData()).astype(np.float64)
    polys = ns.vtk_to_numpy(surf.GetPolys().GetConnectivityArray()).reshape(-1, 3)

    poly = os.path.splitext(a.out)[0] + ".poly"
    with open(poly, "w") as f:
        f.write(f"{len(pts)} 3 0 0\n")
        for i, p in enumerate(pts):
            f.write(f"{i + 1} {p[0]:.6f} {p[1]:.6f} {p[2]:.6f}\n")
        f.write(f"{len(polys)} 0\n")
        for t in polys:
            f.write(f"1\n3 {t[0] + 1} {t[1] + 1} {t[2] + 1}\n")
        f.write("0\n0\n")
    with tempfile.TemporaryDirectory() as tmp:
        src = os.path.join(tmp, "head.poly")
        with open(poly) as fi, open(src, "w") as fo:
            fo.write(fi.read())
        subprocess.run(["tetgen", "-pq1.6a%gQ" % a.max_volume, src], check=True)
        node = np.loadtxt(os.path.join(tmp, "head.1.node"), skiprows=1, comments="#")
        ele = np.loadtxt(os.path.join(tmp, "head.1.ele"), skiprows=1, comments="#", dtype=np.int64)
    first = int(ele[:, 1:5].min())  # TetGen numbers from the .poly's first index (1)
    points = node[:, 1:4]
    tets = ele[:, 1:5] - first

    grid = vtk.vtkUnstructuredGrid()
    vp = vtk.vtkPoints()
    vp.SetData(ns.numpy_to_vtk(points, deep=True))
    grid.SetPoints(vp)
    cells = vtk.vtkCellArray()
    conn_ids = ns.numpy_to_vtkIdTypeArray(tets.ravel().astype(np.int64), deep=True)
    offsets = ns.numpy_to_vtkIdTypeArray(np.arange(0, 4 * len(tets) + 1, 4, dtype=np.int64), deep=True)
    cells.SetData(offsets, conn_ids)
    grid.SetCells(vtk.VTK_TETRA, cells)
    probe = vtk.vtkProbeFilter()
    probe.SetInputData(grid)
    probe.SetSourceData(image)
    probe.Update()
    t1 = ns.vtk_to_numpy(probe.GetOutput().GetPointData().GetScalars()).astype(np.float32)
    arr = ns.numpy_to_vtk(t1, deep=True)
    arr.SetName("t1")
    grid.GetPointData().AddArray(arr)
    w = vtk.vtkXMLUnstructuredGridWriter()
    w.SetFileName(a.out)
    w.SetDataModeToBinary()
    w.SetInputData(grid)
    w.Write()
    print(f"{len(polys)} surface triangles, {len(points)} points, {len(tets)} tets -> {a.out}")


if __name__ == "__main__":
    main()
