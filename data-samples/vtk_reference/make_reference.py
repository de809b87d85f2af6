#!/usr/bin/env python3
"""Reference isosurfaces computed by VTK, for `app/tests/cli_export.rs`.

Run from the repository root with VTK and numpy installed (`pip install vtk numpy`):

    python3 data-samples/vtk_reference/make_reference.py

Writes, next to this script:
- `torus32_u8_iso32.5.{json,ply}`: vtkFlyingEdges3D (and vtkMarchingCubes, counts only) on
  `data-samples/samples/torus32_u8.nrrd` at isovalue 32.5 (read here from the raw NRRD with
  numpy, geometry from its header);
- `ball_tets.vtu`: a small tetrahedral mesh (9^3 lattice points on [-1, 1]^3 split into tets
  by vtkDataSetTriangleFilter, float32 points, point array `distance` = |p - c| as float32);
- `ball_tets_iso0.62.{json,ply}`: vtkContourFilter on that mesh at isovalue 0.62.

The JSON files hold the triangle and vertex counts and the total area (summed in float64
over the output triangles); the PLY files (vtkPLYWriter, binary) hold the triangles.
"""

import json
import os

import numpy as np
import vtk
from vtk.util import numpy_support

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))


def read_raw_nrrd(path):
    """A raw, node-centred NRRD with `sizes`, `spacings`, `axis mins`: (values, spacing, origin)."""
    with open(path, "rb") as f:
        data = f.read()
    header, _, body = data.partition(b"\n\n")
    fields = {}
    for line in header.decode().splitlines()[1:]:
        if line.startswith("#") or ": " not in line:
            continue
        k, v = line.split(": ", 1)
        fields[k] = v
    assert fields["encoding"] == "raw" and fields["type"] == "uint8", fields
    sizes = [int(x) for x in fields["sizes"].split()]
    spacing = [float(x) for x in fields["spacings"].split()]
    origin = [float(x) for x in fields["axis mins"].split()]
    values = np.frombuffer(body, dtype=np.uint8, count=int(np.prod(sizes)))
    return values, sizes, spacing, origin


def summary(poly):
    """Counts and float64 area of a vtkPolyData of triangles."""
    pts = numpy_support.vtk_to_numpy(poly.GetPoints().GetData()).astype(np.float64)
    polys = numpy_support.vtk_to_numpy(poly.GetPolys().GetConnectivityArray()).reshape(-1, 3)
    offsets = numpy_support.vtk_to_numpy(poly.GetPolys().GetOffsetsArray())
    assert np.all(np.diff(offsets) == 3), "triangles only"
    a, b, c = pts[polys[:, 0]], pts[polys[:, 1]], pts[polys[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum()
    return {
        "triangles": int(polys.shape[0]),
        "vertices": int(pts.shape[0]),
        "area": float(area),
    }


def write_ply(poly, path):
    w = vtk.vtkPLYWriter()
    w.SetInputData(poly)
    w.SetFileName(path)
    w.SetFileTypeToBinary()
    w.Write()


def write_json(path, record):
    with open(path, "w") as f:
        json.dump(record, f, indent=2, sort_keys=True)
        f.write("\n")


def grid_reference():
    src = os.path.join(ROOT, "data-samples", "samples", "torus32_u8.nrrd")
    values, sizes, spacing, origin = read_raw_nrrd(src)
    image = vtk.vtkImageData()
    image.SetDimensions(*sizes)
    image.SetSpacing(*spacing)
    image.SetOrigin(*origin)
    arr = numpy_support.numpy_to_vtk(values, deep=True, array_type=vtk.VTK_UNSIGNED_CHAR)
    arr.SetName("values")
    image.GetPointData().SetScalars(arr)
    iso = 32.5
    fe = vtk.vtkFlyingEdges3D()
    fe.SetInputData(image)
    fe.SetValue(0, iso)
    fe.ComputeNormalsOff()
    fe.ComputeGradientsOff()
    fe.ComputeScalarsOff()
    fe.Update()
    mc = vtk.vtkMarchingCubes()
    mc.SetInputData(image)
    mc.SetValue(0, iso)
    mc.ComputeNormalsOff()
    mc.ComputeScalarsOff()
    mc.Update()
    record = summary(fe.GetOutput())
    record["marching_cubes"] = summary(mc.GetOutput())
    record.update(
        {
            "input": "data-samples/samples/torus32_u8.nrrd",
            "isovalue": iso,
            "filter": "vtkFlyingEdges3D",
            "vtk_version": vtk.vtkVersion.GetVTKVersion(),
        }
    )
    write_json(os.path.join(HERE, "torus32_u8_iso32.5.json"), record)
    write_ply(fe.GetOutput(), os.path.join(HERE, "torus32_u8_iso32.5.ply"))
    print("grid", record)


def tet_reference():
    n = 9
    image = vtk.vtkImageData()
    image.SetDimensions(n, n, n)
    image.SetSpacing(2.0 / (n - 1), 2.0 / (n - 1), 2.0 / (n - 1))
    image.SetOrigin(-1.0, -1.0, -1.0)
    tets = vtk.vtkDataSetTriangleFilter()
    tets.SetInputData(image)
    tets.TetrahedraOnlyOn()
    tets.Update()
    grid = tets.GetOutput()
    pts = numpy_support.vtk_to_numpy(grid.GetPoints().GetData()).astype(np.float32)
    points = vtk.vtkPoints()
    points.SetData(numpy_support.numpy_to_vtk(pts, deep=True, array_type=vtk.VTK_FLOAT))
    grid.SetPoints(points)
    centre = np.array([0.05, -0.03, 0.02], dtype=np.float64)
    dist = np.linalg.norm(pts.astype(np.float64) - centre, axis=1).astype(np.float32)
    d = numpy_support.numpy_to_vtk(dist, deep=True, array_type=vtk.VTK_FLOAT)
    d.SetName("distance")
    grid.GetPointData().Initialize()
    grid.GetPointData().SetScalars(d)
    w = vtk.vtkXMLUnstructuredGridWriter()
    w.SetInputData(grid)
    w.SetFileName(os.path.join(HERE, "ball_tets.vtu"))
    w.SetDataModeToAppended()
    w.EncodeAppendedDataOff()
    w.SetCompressorTypeToZLib()
    w.Write()
    iso = 0.62
    contour = vtk.vtkContourFilter()
    contour.SetInputData(grid)
    contour.SetValue(0, iso)
    contour.ComputeNormalsOff()
    contour.ComputeScalarsOff()
    contour.Update()
    record = summary(contour.GetOutput())
    record.update(
        {
            "input": "data-samples/vtk_reference/ball_tets.vtu",
            "tets": int(grid.GetNumberOfCells()),
            "isovalue": iso,
            "filter": "vtkContourFilter",
            "vtk_version": vtk.vtkVersion.GetVTKVersion(),
        }
    )
    write_json(os.path.join(HERE, "ball_tets_iso0.62.json"), record)
    write_ply(contour.GetOutput(), os.path.join(HERE, "ball_tets_iso0.62.ply"))
    print("tets", record)


if __name__ == "__main__":
    grid_reference()
    tet_reference()
