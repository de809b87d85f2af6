#!/usr/bin/env python3
"""Writes the image reader fixtures (formats/tests/data/{metaimage,vtk_image,tiff}/) with the
reference libraries, and what those libraries report about them (truth.json per folder).

Run from anywhere: `python make_images.py` (needs SimpleITK, vtk, tifffile, Pillow, pynrrd,
numpy; /work/venvs/peers/bin/python has them). The Rust tests never run it: they read the
committed files and compare the readers' volumes with truth.json.

Truth is what the *libraries* say when they read the files back (SimpleITK's spacing, origin,
direction, TransformIndexToPhysicalPoint; VTK's GetPoint / TransformIndexToPhysicalPoint and
array values; tifffile's pages, ImageJ metadata and resolution tags; Pillow for the LZW and
PackBits files tifffile cannot decode without imagecodecs). Files the libraries cannot write
(big-endian MetaImage, HeaderSize, pattern and LIST data files) are written here by hand, and
their truth is what SimpleITK reads from them.

`*.twin.nrrd` files (pynrrd) hold the same voxels and geometry as NRRD, for the app test that
renders each format and its twin and compares the depth images.
"""
import json
import os
import zlib

import numpy as np
import nrrd
import SimpleITK as sitk
import tifffile
import vtk
from PIL import Image
from vtk.util import numpy_support as ns

HERE = os.path.dirname(os.path.abspath(__file__))
NX, NY, NZ = 10, 8, 6


def field(nx=NX, ny=NY, nz=NZ):
    """A distorted sphere distance field, [z, y, x] (x fastest in memory), 0..~140."""
    z, y, x = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    cx, cy, cz = (nx - 1) / 2, (ny - 1) / 2, (nz - 1) / 2
    d = np.sqrt(((x - cx) / cx) ** 2 + ((y - cy) / cy) ** 2 + ((z - cz) / cz) ** 2)
    return 80 * d + 6 * x / nx + 3 * y / ny


def dtype_name(dt):
    return {"uint8": "u8", "int8": "i8", "uint16": "u16", "int16": "i16", "uint32": "u32",
            "int32": "i32", "float16": "f32", "float32": "f32", "float64": "f64"}[np.dtype(dt).name]


def corners(dims):
    return [(i, j, k) for k in (0, dims[2] - 1) for j in (0, dims[1] - 1) for i in (0, dims[0] - 1)]


def sample_indices(dims):
    mid = tuple(d // 2 for d in dims)
    return corners(dims) + [mid, (1, 2, 3), (dims[0] - 2, 1, dims[2] - 2)]


def out(folder):
    d = os.path.join(HERE, folder)
    os.makedirs(d, exist_ok=True)
    return d


def write_twin(path, arr_zyx, spacing, origin, dirs, space):
    """NRRD twin: same voxels (x fastest), space directions = axis directions * spacing."""
    data = np.asarray(arr_zyx).transpose(2, 1, 0)  # pynrrd wants [x, y, z] in Fortran order
    header = {
        "space directions": np.array([np.array(dirs[a]) * spacing[a] for a in range(3)]),
        "space origin": np.array(origin, dtype=float),
        "encoding": "raw",
        "endian": "little",
    }
    if space:
        header["space"] = space
    else:
        header["space dimension"] = 3
    nrrd.write(path, data, header, index_order="F")


# --------------------------------------------------------------------------- MetaImage

def sitk_truth(name, img, open_name=None, twin=None, iso=None, steps=1):
    """What SimpleITK reports about `img` (read back from the file)."""
    dims = list(img.GetSize())[:3]
    arr = sitk.GetArrayFromImage(img)  # [t,] z, y, x
    nd = img.GetDimension()
    d = np.array(img.GetDirection()).reshape(nd, nd)
    dirs = [[float(d[r, a]) for r in range(3)] for a in range(3)]
    samples, world = [], []
    for (i, j, k) in sample_indices(dims):
        v = arr[(0,) * (nd - 3) + (k, j, i)] if nd == 4 else arr[k, j, i]
        samples.append([i, j, k, float(v)])
    for (i, j, k) in corners(dims):
        idx = (i, j, k) if nd == 3 else (i, j, k, 0)
        p = img.TransformIndexToPhysicalPoint(idx)
        world.append([i, j, k, [float(x) for x in p[:3]]])
    t = {
        "file": name,
        "open": open_name or name,
        "dims": dims,
        "steps": steps,
        "dtype": dtype_name(arr.dtype),
        "spacing": [float(s) for s in img.GetSpacing()[:3]],
        "origin": [float(o) for o in img.GetOrigin()[:3]],
        "axis_directions": dirs,
        "world_frame": "LPS",
        "samples": samples,
        "world_corners": world,
        "twin": twin,
        "iso": iso,
    }
    if steps > 1:
        last = arr[steps - 1]
        t["last_step_samples"] = [[i, j, k, float(last[k, j, i])] for (i, j, k) in sample_indices(dims)]
        t["time_spacing"] = float(img.GetSpacing()[3])
        t["time_origin"] = float(img.GetOrigin()[3])
    return t


def metaimage():
    d = out("metaimage")
    truths = []
    f = field()

    def image(arr, spacing, origin, direction):
        img = sitk.GetImageFromArray(arr)
        img.SetSpacing(spacing)
        img.SetOrigin(origin)
        img.SetDirection(direction)
        return img

    def save(img, name, compress, twin_space="left-posterior-superior", iso=None):
        p = os.path.join(d, name)
        sitk.WriteImage(img, p, useCompression=compress)
        back = sitk.ReadImage(p)
        twin = None
        if iso is not None:
            twin = name.rsplit(".", 1)[0] + ".twin.nrrd"
            dirs = np.array(back.GetDirection()).reshape(3, 3)
            write_twin(os.path.join(d, twin), sitk.GetArrayFromImage(back),
                       back.GetSpacing(), back.GetOrigin(),
                       [dirs[:, a] for a in range(3)], twin_space)
        truths.append(sitk_truth(name, back, twin=twin, iso=iso))

    c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
    oblique = (c, -s, 0, s, c, 0, 0, 0, 1)  # rows: a rotation about z
    # Oriented, int16, LOCAL, uncompressed (memory-mapped).
    save(image((f - 40).astype(np.int16), (0.8, 1.1, 1.5), (-10.0, 5.0, 20.0), oblique),
         "oblique_i16.mha", False, iso=20.0)
    # float32, LOCAL, zlib.
    save(image(f.astype(np.float32), (1.0, 0.5, 2.0), (3.0, -4.0, 0.0), (1, 0, 0, 0, 1, 0, 0, 0, 1)),
         "float_zlib.mha", True, iso=60.0)
    # uint8 detached .mhd + .raw, a permuted (sagittal-like) direction.
    perm = (0, 0, 1, 1, 0, 0, 0, 1, 0)
    save(image(np.clip(f * 1.5, 0, 255).astype(np.uint8), (0.7, 0.7, 1.2), (0.0, 0.0, 0.0), perm),
         "sagittal_u8.mhd", False, iso=90.0)
    # uint16 detached, compressed .zraw, flipped axes.
    flip = (-1, 0, 0, 0, -1, 0, 0, 0, 1)
    save(image((f * 100).astype(np.uint16), (0.5, 0.6, 0.7), (50.0, 40.0, -3.0), flip),
         "flipped_u16.mhd", True, iso=6000.0)
    # 4D: three steps of uint8.
    steps = [sitk.GetImageFromArray(np.clip(f * 1.5 + 10 * t, 0, 255).astype(np.uint8)) for t in range(3)]
    for st in steps:
        st.SetSpacing((1.0, 1.0, 1.0))
    four = sitk.JoinSeries(steps, 0.0, 2.5)
    p = os.path.join(d, "series_4d.mha")
    sitk.WriteImage(four, p)
    truths.append(sitk_truth("series_4d.mha", sitk.ReadImage(p), steps=3))

    # Hand-written headers for what SimpleITK does not write; truth is SimpleITK reading them.
    def hand(name, header, data_files):
        for fname, payload in data_files.items():
            with open(os.path.join(d, fname), "wb") as fh:
                fh.write(payload)
        p = os.path.join(d, name)
        if name.endswith(".mha"):
            return p  # written with its data by the caller
        with open(p, "w") as fh:
            fh.write(header)
        return p

    def header(dtype, extra, data_file, msb=False, dims=(NX, NY, NZ)):
        return ("ObjectType = Image\nNDims = 3\nBinaryData = True\n"
                f"BinaryDataByteOrderMSB = {'True' if msb else 'False'}\n"
                f"CompressedData = False\n{extra}"
                f"DimSize = {dims[0]} {dims[1]} {dims[2]}\n"
                f"ElementSpacing = 0.9 1.1 1.3\nOffset = 1 2 3\n"
                f"ElementType = {dtype}\nElementDataFile = {data_file}\n")

    i32 = (f * 1000 - 30000).astype(np.int32)
    # Big-endian MET_INT, LOCAL.
    p = os.path.join(d, "bigendian_i32.mha")
    with open(p, "wb") as fh:
        fh.write(header("MET_INT", "", "LOCAL", msb=True).encode() + i32.astype(">i4").tobytes())
    truths.append(sitk_truth("bigendian_i32.mha", sitk.ReadImage(p)))
    # HeaderSize = -1: 37 junk bytes before the data in the .raw.
    i16 = (f * 10).astype(np.int16)
    hand("headersize_end.mhd", header("MET_SHORT", "HeaderSize = -1\n", "headersize_end.raw"),
         {"headersize_end.raw": b"J" * 37 + i16.tobytes()})
    truths.append(sitk_truth("headersize_end.mhd", sitk.ReadImage(os.path.join(d, "headersize_end.mhd"))))
    # HeaderSize = 16.
    hand("headersize_16.mhd", header("MET_SHORT", "HeaderSize = 16\n", "headersize_16.raw"),
         {"headersize_16.raw": b"H" * 16 + i16.tobytes()})
    truths.append(sitk_truth("headersize_16.mhd", sitk.ReadImage(os.path.join(d, "headersize_16.mhd"))))
    # A pattern: one file per z slice, numbered 1, 3, 5, ... (min 1, max 11, step 2).
    u8 = np.clip(f * 1.5, 0, 255).astype(np.uint8)
    files = {f"slices/pat_{1 + 2 * k:03d}.raw": u8[k].tobytes() for k in range(NZ)}
    os.makedirs(os.path.join(d, "slices"), exist_ok=True)
    hand("pattern_u8.mhd", header("MET_UCHAR", "", "slices/pat_%03d.raw 1 11 2"), files)
    truths.append(sitk_truth("pattern_u8.mhd", sitk.ReadImage(os.path.join(d, "pattern_u8.mhd"))))
    # LIST: one file per z slice, names listed after the header.
    files = {f"slices/list_{k}.raw": u8[k].tobytes() for k in range(NZ)}
    listing = "LIST\n" + "".join(f"slices/list_{k}.raw\n" for k in range(NZ))
    hand("list_u8.mhd", header("MET_UCHAR", "", listing.rstrip("\n")), files)
    truths.append(sitk_truth("list_u8.mhd", sitk.ReadImage(os.path.join(d, "list_u8.mhd"))))

    with open(os.path.join(d, "truth.json"), "w") as fh:
        json.dump(truths, fh, indent=1)


# --------------------------------------------------------------------------- VTK

EXTENT = (2, 2 + NX - 1, -1, -1 + NY - 1, 0, NZ - 1)


def vtk_image():
    im = vtk.vtkImageData()
    im.SetExtent(*EXTENT)
    im.SetOrigin(1.5, -2.0, 4.0)
    im.SetSpacing(0.6, 0.9, 1.2)
    c, s = np.cos(np.radians(20)), np.sin(np.radians(20))
    im.SetDirectionMatrix(1, 0, 0, 0, c, -s, 0, s, c)  # rows: a rotation about x
    f = field()
    temp = ns.numpy_to_vtk(f.astype(np.float32).ravel(), deep=True)
    temp.SetName("temperature")
    label = ns.numpy_to_vtk(np.clip(f * 1.5, 0, 255).astype(np.uint8).ravel(), deep=True)
    label.SetName("label")
    vel = ns.numpy_to_vtk(np.stack([f.ravel()] * 3, axis=1).astype(np.float32), deep=True)
    vel.SetName("velocity")
    im.GetPointData().AddArray(label)
    im.GetPointData().SetScalars(temp)  # active, though not the first array
    im.GetPointData().AddArray(vel)
    return im


def vtk_truth(name, reader_cls, path, arrays, twin=None, iso=None, rectilinear=False):
    r = reader_cls()
    r.SetFileName(path)
    r.Update()
    data = r.GetOutput()
    dims = list(data.GetDimensions())
    pd = data.GetPointData()
    scalars = pd.GetScalars()
    t = {"file": name, "open": name, "dims": dims, "steps": 1, "twin": twin, "iso": iso,
         "world_frame": "unknown", "active": scalars.GetName() if scalars else None, "arrays": {}}
    for a in arrays:
        arr = ns.vtk_to_numpy(pd.GetArray(a))
        t["arrays"][a] = {"dtype": dtype_name(arr.dtype), "components": 1 if arr.ndim == 1 else arr.shape[1]}
        if arr.ndim == 1:
            t["arrays"][a]["samples"] = [[i, j, k, float(arr[i + dims[0] * (j + dims[1] * k)])]
                                         for (i, j, k) in sample_indices(dims)]
    world = []
    for (i, j, k) in corners(dims):
        p = data.GetPoint(i + dims[0] * (j + dims[1] * k))
        world.append([i, j, k, [float(x) for x in p]])
    t["world_corners"] = world
    if not rectilinear:
        t["spacing"] = [float(x) for x in data.GetSpacing()]
        m = data.GetDirectionMatrix()
        t["axis_directions"] = [[m.GetElement(r, a) for r in range(3)] for a in range(3)]
    else:
        t["coordinates"] = [[float(x) for x in ns.vtk_to_numpy(c)] for c in
                            (data.GetXCoordinates(), data.GetYCoordinates(), data.GetZCoordinates())]
    return t


def vtk_files():
    d = out("vtk_image")
    im = vtk_image()
    truths = []
    names = ["temperature", "label", "velocity"]
    variants = [
        ("ascii.vti", lambda w: w.SetDataModeToAscii()),
        ("binary.vti", lambda w: (w.SetDataModeToBinary(), w.SetCompressorTypeToNone())),
        ("binary_zlib.vti", lambda w: (w.SetDataModeToBinary(), w.SetCompressorTypeToZLib(), w.SetBlockSize(256))),
        ("appended_raw.vti", lambda w: (w.SetDataModeToAppended(), w.EncodeAppendedDataOff(), w.SetCompressorTypeToNone())),
        ("appended_base64.vti", lambda w: (w.SetDataModeToAppended(), w.EncodeAppendedDataOn(), w.SetCompressorTypeToNone())),
        ("appended_lz4.vti", lambda w: (w.SetDataModeToAppended(), w.EncodeAppendedDataOff(), w.SetCompressorTypeToLZ4(), w.SetBlockSize(200))),
        ("appended_zlib_u64.vti", lambda w: (w.SetDataModeToAppended(), w.EncodeAppendedDataOff(), w.SetCompressorTypeToZLib(), w.SetHeaderTypeToUInt64())),
        ("binary_bigendian.vti", lambda w: (w.SetDataModeToBinary(), w.SetCompressorTypeToNone(), w.SetByteOrderToBigEndian())),
    ]
    for name, setup in variants:
        w = vtk.vtkXMLImageDataWriter()
        w.SetInputData(im)
        setup(w)
        p = os.path.join(d, name)
        w.SetFileName(p)
        assert w.Write() == 1, name
        twin = None
        if name == "binary_zlib.vti":
            twin = "binary_zlib.twin.nrrd"
            m = im.GetDirectionMatrix()
            dirs = [[m.GetElement(r, a) for r in range(3)] for a in range(3)]
            # The twin's origin is the world position of the first sample (extent start).
            p0 = im.GetPoint(0)
            write_twin(os.path.join(d, twin), ns.vtk_to_numpy(im.GetPointData().GetArray("temperature")).reshape(NZ, NY, NX),
                       im.GetSpacing(), p0, dirs, None)
        truths.append(vtk_truth(name, vtk.vtkXMLImageDataReader, p, names, twin=twin,
                                iso=60.0 if twin else None))

    # Legacy structured points (no direction in the legacy format): origin at the extent start.
    sp = vtk.vtkImageData()
    sp.SetDimensions(NX, NY, NZ)
    sp.SetOrigin(-3.0, 2.0, 0.5)
    sp.SetSpacing(0.7, 0.8, 1.9)
    f = field()
    a = ns.numpy_to_vtk((f - 40).astype(np.int16).ravel(), deep=True)
    a.SetName("density")
    b = ns.numpy_to_vtk(f.astype(np.float64).ravel(), deep=True)
    b.SetName("distance")
    sp.GetPointData().SetScalars(a)
    sp.GetPointData().AddArray(b)
    for name, binary, version in [("points_v51_ascii.vtk", False, 51), ("points_v51_binary.vtk", True, 51),
                                  ("points_v42_binary.vtk", True, 42)]:
        w = vtk.vtkStructuredPointsWriter()
        w.SetInputData(sp)
        w.SetFileName(os.path.join(d, name))
        w.SetFileTypeToBinary() if binary else w.SetFileTypeToASCII()
        w.SetFileVersion(version)
        assert w.Write() == 1
        twin = None
        if name == "points_v51_binary.vtk":
            twin = "points_v51_binary.twin.nrrd"
            write_twin(os.path.join(d, twin), (f - 40).astype(np.int16), sp.GetSpacing(), sp.GetOrigin(),
                       [[1, 0, 0], [0, 1, 0], [0, 0, 1]], None)
        truths.append(vtk_truth(name, vtk.vtkStructuredPointsReader, os.path.join(d, name),
                                ["density", "distance"], twin=twin, iso=20.0 if twin else None))

    # Legacy rectilinear grid: explicit, unevenly spaced coordinates.
    rg = vtk.vtkRectilinearGrid()
    rg.SetDimensions(NX, NY, NZ)
    xs = np.cumsum(np.linspace(0.5, 1.4, NX)) - 3.0
    ys = np.cumsum(np.linspace(1.0, 0.4, NY))
    zs = np.array([0.0, 0.5, 1.5, 3.0, 5.0, 7.5])[:NZ]
    rg.SetXCoordinates(ns.numpy_to_vtk(xs.astype(np.float64), deep=True))
    rg.SetYCoordinates(ns.numpy_to_vtk(ys.astype(np.float32), deep=True))
    rg.SetZCoordinates(ns.numpy_to_vtk(zs.astype(np.float64), deep=True))
    c = ns.numpy_to_vtk(f.astype(np.float32).ravel(), deep=True)
    c.SetName("distance")
    rg.GetPointData().SetScalars(c)
    for name, binary in [("rectilinear_ascii.vtk", False), ("rectilinear_binary.vtk", True)]:
        w = vtk.vtkRectilinearGridWriter()
        w.SetInputData(rg)
        w.SetFileName(os.path.join(d, name))
        w.SetFileTypeToBinary() if binary else w.SetFileTypeToASCII()
        assert w.Write() == 1
        truths.append(vtk_truth(name, vtk.vtkRectilinearGridReader, os.path.join(d, name),
                                ["distance"], rectilinear=True))
    with open(os.path.join(d, "truth.json"), "w") as fh:
        json.dump(truths, fh, indent=1)


# --------------------------------------------------------------------------- TIFF

def tiff_truth(name, arr_zyx, spacing, steps=1, open_name=None, twin=None, iso=None, reader="tifffile",
               unit=None, time_interval=None, options_spacing=None):
    dims = [arr_zyx.shape[-1], arr_zyx.shape[-2], arr_zyx.shape[-3]]
    first = arr_zyx[0] if steps > 1 else arr_zyx
    t = {"file": name, "open": open_name or name, "dims": dims, "steps": steps,
         "dtype": dtype_name(arr_zyx.dtype), "spacing": [float(s) for s in spacing],
         "origin": [0.0, 0.0, 0.0], "world_frame": "unknown", "reader": reader,
         "samples": [[i, j, k, float(first[k, j, i])] for (i, j, k) in sample_indices(dims)],
         "world_corners": [[i, j, k, [i * spacing[0], j * spacing[1], k * spacing[2]]] for (i, j, k) in corners(dims)],
         "twin": twin, "iso": iso, "unit": unit, "options_spacing": options_spacing}
    if steps > 1:
        last = arr_zyx[steps - 1]
        t["last_step_samples"] = [[i, j, k, float(last[k, j, i])] for (i, j, k) in sample_indices(dims)]
        t["time_interval"] = time_interval
    return t


def tiff_files():
    d = out("tiff")
    truths = []
    f = field()

    # Plain multi-page uint16: no spacing in the file (the test passes --spacing-like options).
    p = os.path.join(d, "plain_u16.tif")
    tifffile.imwrite(p, (f * 100).astype(np.uint16))
    back = tifffile.imread(p)
    truths.append(tiff_truth("plain_u16.tif", back, [1.0, 1.0, 1.0]))
    truths.append(tiff_truth("plain_u16.tif", back, [0.5, 0.25, 2.0], options_spacing=[0.5, 0.25, 2.0]))

    # ImageJ float32 stack: 0.4 x 0.3 um pixels, 1.7 um slices.
    p = os.path.join(d, "imagej_f32.tif")
    tifffile.imwrite(p, f.astype(np.float32), imagej=True, resolution=(1 / 0.4, 1 / 0.3),
                     metadata={"spacing": 1.7, "unit": "um", "axes": "ZYX"})
    with tifffile.TiffFile(p) as tf:
        ij = tf.imagej_metadata
        xr = tf.pages[0].tags["XResolution"].value
        yr = tf.pages[0].tags["YResolution"].value
        back = tf.asarray()
    spacing = [xr[1] / xr[0], yr[1] / yr[0], ij["spacing"]]
    twin = "imagej_f32.twin.nrrd"
    write_twin(os.path.join(d, twin), back, spacing, [0, 0, 0], [[1, 0, 0], [0, 1, 0], [0, 0, 1]], None)
    truths.append(tiff_truth("imagej_f32.tif", back, spacing, twin=twin, iso=60.0, unit=ij["unit"]))

    # ImageJ hyperstack: 3 frames of NZ slices, uint8, 0.25 s between frames.
    hyper = np.stack([np.clip(f * 1.5 + 20 * t, 0, 255).astype(np.uint8) for t in range(3)])
    p = os.path.join(d, "imagej_frames_u8.tif")
    tifffile.imwrite(p, hyper, imagej=True, resolution=(2.0, 2.0),
                     metadata={"spacing": 3.0, "unit": "um", "axes": "TZYX", "finterval": 0.25})
    with tifffile.TiffFile(p) as tf:
        ij = tf.imagej_metadata
        back = tf.asarray()
        xr = tf.pages[0].tags["XResolution"].value
    assert back.shape == hyper.shape, back.shape
    spacing = [xr[1] / xr[0], xr[1] / xr[0], ij["spacing"]]
    truths.append(tiff_truth("imagej_frames_u8.tif", back, spacing, steps=ij["frames"],
                             time_interval=ij["finterval"], unit=ij["unit"]))

    # Other sample types, deflate-compressed (tifffile's zlib).
    for name, arr in [("deflate_i32.tif", (f * 1000 - 50000).astype(np.int32)),
                      ("deflate_f64.tif", f.astype(np.float64)),
                      ("plain_i8.tif", (f - 70).clip(-128, 127).astype(np.int8)),
                      ("plain_i16.tif", (f * 50 - 3000).astype(np.int16)),
                      # Half floats: read as f32 (every f16 is an f32).
                      ("plain_f16.tif", f.astype(np.float16))]:
        p = os.path.join(d, name)
        tifffile.imwrite(p, arr, compression="zlib" if name.startswith("deflate") else None)
        truths.append(tiff_truth(name, tifffile.imread(p), [1.0, 1.0, 1.0]))

    # LZW and PackBits (Pillow with libtiff writes them; Pillow reads them back).
    u16 = (f * 100).astype(np.uint16)
    for name, comp in [("lzw_u16.tif", "tiff_lzw"), ("packbits_u8.tif", "packbits")]:
        arr = u16 if "u16" in name else np.clip(f * 1.5, 0, 255).astype(np.uint8)
        frames = [Image.fromarray(arr[k]) for k in range(NZ)]
        p = os.path.join(d, name)
        frames[0].save(p, save_all=True, append_images=frames[1:], compression=comp)
        im = Image.open(p)
        pages = []
        for k in range(im.n_frames):
            im.seek(k)
            pages.append(np.array(im))
        back = np.stack(pages).astype(arr.dtype)
        assert (back == arr).all(), name
        truths.append(tiff_truth(name, back, [1.0, 1.0, 1.0], reader="Pillow"))

    # Numbered 2D slices: one volume (int16), ImageJ resolution in the first file.
    os.makedirs(os.path.join(d, "slices"), exist_ok=True)
    i16 = (f * 50 - 3000).astype(np.int16)
    for k in range(NZ):
        tifffile.imwrite(os.path.join(d, "slices", f"slice_{k:03d}.tif"), i16[k], imagej=True,
                         resolution=(1 / 0.5, 1 / 0.5), metadata={"unit": "um"})
    back = np.stack([tifffile.imread(os.path.join(d, "slices", f"slice_{k:03d}.tif")) for k in range(NZ)])
    with tifffile.TiffFile(os.path.join(d, "slices", "slice_000.tif")) as tf:
        xr = tf.pages[0].tags["XResolution"].value
    spacing = [xr[1] / xr[0], xr[1] / xr[0], 1.0]
    twin = "slices.twin.nrrd"
    write_twin(os.path.join(d, twin), back, spacing, [0, 0, 0], [[1, 0, 0], [0, 1, 0], [0, 0, 1]], None)
    truths.append(tiff_truth("slices/slice_000.tif", back, spacing, open_name="slices/slice_%03d.tif",
                             twin=twin, iso=200.0))
    truths.append(tiff_truth("slices/slice_000.tif", back, [spacing[0], spacing[1], 2.5],
                             open_name="slices/slice_*.tif", options_spacing=[9.0, 9.0, 2.5]))
    with open(os.path.join(d, "truth.json"), "w") as fh:
        json.dump(truths, fh, indent=1)


if __name__ == "__main__":
    metaimage()
    vtk_files()
    tiff_files()
    print("versions:", "SimpleITK", sitk.Version.VersionString(), "| VTK", vtk.vtkVersion.GetVTKVersion(),
          "| tifffile", tifffile.__version__, "| Pillow", Image.__version__ if hasattr(Image, "__version__") else "?",
          "| pynrrd", nrrd.__version__, "| numpy", np.__version__)
