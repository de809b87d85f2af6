#!/usr/bin/env python3
"""Writes the NIfTI / Analyze test fixtures of formats/tests/nifti_read.rs and the values
nibabel reports for them (expected.json).

Run from this directory with a Python that has nibabel (tested with nibabel 5.4.2, numpy 2):

    python3 make_nifti.py

- Copies files from nibabel's own test data (nibabel/tests/data, MIT licence): files written
  by other programs (FSL, SPM, AFNI, nibabel itself) that nibabel's test suite checks.
- Writes small volumes with nibabel for the cases those do not cover: big-endian, scaled
  int16, qform only with qfac -1, an oblique sform that differs from the qform, a .hdr/.img
  pair, a gzipped pair (.hdr.gz/.img.gz), float64, uint16, NIfTI-2 big-endian, SPM2 Analyze.
- expected.json: per file, what nibabel reads: shape, on-disk dtype and byte order, the
  affine (nibabel's get_best_affine: RAS+, in the file's units), the space unit, scl
  slope/intercept (null: no scaling), pixdim[4]/toffset, a few voxels (stored and scaled),
  and the world position of the 8 corner voxels. For header-only files (.hdr without .img)
  only the header fields. `profiles`: scaled_i16.nii's physical values along x on the rows
  (j, k) in {5, 6} x {4, 5}.

Nothing here is computed by Isoscope: the Rust test compares its reader with these values.
"""

import json
import os
import shutil

import nibabel as nib
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
NIB_DATA = os.path.join(os.path.dirname(nib.__file__), "tests", "data")

# Files copied from nibabel's test data.
COPIED = [
    "anatomical.nii",  # 3D int16, big-endian, sform = qform (flipped x)
    "functional.nii",  # 4D int16, 20 volumes, TR 2 s
    "example4d.nii.gz",  # 4D int16, oblique qform/sform (FSL)
    "example_nifti2.nii.gz",  # NIfTI-2, 4D int16, oblique
    "analyze.hdr",  # Analyze 7.5 header (SPM origin, funused1 scale), no .img
    "nifti1.hdr",  # NIfTI-1 pair header (ni1), no .img
    "nifti2.hdr",  # NIfTI-2 pair header (ni2), no .img
]


def ramp(shape, dtype, lo, hi):
    """A smooth field (distance from an off-centre point) scaled to [lo, hi] in `dtype`."""
    idx = np.indices(shape, dtype=np.float64)
    c = [0.37 * (s - 1) for s in shape]
    d = np.sqrt(sum((idx[a] - c[a]) ** 2 for a in range(len(shape))))
    d = d / d.max()
    v = lo + (hi - lo) * d
    if np.issubdtype(np.dtype(dtype), np.integer):
        v = np.round(v)
    return v.astype(dtype)


def rot(ax, ay, az):
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def affine(linear, offset):
    a = np.eye(4)
    a[:3, :3] = linear
    a[:3, 3] = offset
    return a


def write_generated():
    shape = (12, 10, 8)

    # Big-endian int16 with a plain sform and qform.
    hdr = nib.Nifti1Header(endianness=">")
    img = nib.Nifti1Image(ramp(shape, np.int16, -300, 900), affine(np.diag([1.5, 2.0, 2.5]), [-9, 10, -4]), hdr)
    img.set_data_dtype(np.int16)
    img.header.set_xyzt_units("mm")
    img.to_filename("big_endian.nii")

    # Scaled int16: stored values, then scl_slope 2 / scl_inter -1024 written into the header
    # by nibabel (nibabel recomputes scaling from the data when it saves an array).
    stored = ramp(shape, np.int16, 0, 1500)
    img = nib.Nifti1Image(stored, affine(np.diag([1.0, 1.0, 1.0]), [0, 0, 0]))
    img.set_data_dtype(np.int16)
    img.to_filename("scaled_i16.nii")
    hdr = nib.load("scaled_i16.nii").header.copy()
    hdr["scl_slope"] = 2.0
    hdr["scl_inter"] = -1024.0
    with open("scaled_i16.nii", "r+b") as f:
        hdr.write_to(f)

    # qform only, left-handed voxel frame (qfac -1), rotated.
    lin = rot(0.2, -0.1, 0.3) @ np.diag([1.2, 0.8, 2.0]) @ np.diag([1, 1, -1])
    img = nib.Nifti1Image(ramp(shape, np.uint8, 0, 255), None)
    img.set_qform(affine(lin, [5.0, -7.0, 12.0]), code=1)
    img.set_sform(None, code=0)
    img.to_filename("qform_qfac.nii")

    # Oblique, sheared sform (code 2) that wins over a different qform (code 1).
    lin = rot(0.4, 0.25, -0.5) @ np.array([[1.0, 0.3, 0.0], [0.0, 1.1, 0.0], [0.0, 0.0, 1.7]])
    img = nib.Nifti1Image(ramp(shape, np.float32, -1.0, 3.0), None)
    img.set_qform(affine(np.diag([3.0, 3.0, 3.0]), [100, 100, 100]), code=1)
    img.set_sform(affine(lin, [-20.0, 15.0, 3.5]), code=2)
    img.to_filename("sform_oblique.nii")

    # A .hdr/.img pair (magic ni1), float32.
    img = nib.Nifti1Pair(ramp(shape, np.float32, 10.0, 20.0), affine(np.diag([0.9, 0.9, 1.8]), [1, 2, 3]))
    img.to_filename("pair.hdr")

    # A gzipped pair: pair_gz.hdr.gz + pair_gz.img.gz, int8.
    img = nib.Nifti1Pair(ramp(shape, np.int8, -100, 100), affine(np.diag([-1.0, 1.0, 1.0]), [11, -5, 0]))
    img.to_filename("pair_gz.img.gz")

    # float64, gzipped single file.
    img = nib.Nifti1Image(ramp(shape, np.float64, -0.5, 0.25), affine(np.diag([0.5, 0.5, 0.5]), [0, 0, 0]))
    img.to_filename("f64.nii.gz")

    # uint16, little-endian, uncompressed (memory-mapped without a copy); lengths in microns
    # (nibabel's affine stays in the file's unit).
    img = nib.Nifti1Image(ramp(shape, np.uint16, 100, 60000), affine(np.diag([2000.0, 2000.0, 2000.0]), [-11000, -9000, -7000]))
    img.header.set_xyzt_units("micron")
    img.to_filename("u16.nii")

    # NIfTI-2, big-endian, uncompressed, 4D (3 steps, 0.5 s).
    data = np.stack([ramp(shape, np.int32, -5000 * (t + 1), 7000) for t in range(3)], axis=-1)
    hdr = nib.Nifti2Header(endianness=">")
    img = nib.Nifti2Image(data, affine(rot(0.0, 0.0, 0.5) @ np.diag([1.0, 2.0, 3.0]), [4, 5, 6]), hdr)
    img.set_data_dtype(np.int32)
    img.header.set_xyzt_units("mm", "sec")
    img.header["pixdim"][4] = 0.5
    img.to_filename("nifti2_be_4d.nii")

    # SPM2 Analyze 7.5 pair: origin voxel and a scale factor (funused1).
    img = nib.Spm2AnalyzeImage(ramp(shape, np.int16, 0, 2000), affine(np.diag([-2.0, 2.0, 3.0]), [10, -8, -12]))
    img.header.set_slope_inter(0.25)
    img.to_filename("analyze_spm.hdr")
    # nibabel also writes SPM's .mat side file, which overrides the header's orientation
    # when nibabel loads the pair; Isoscope does not read it, so compare with the header.
    os.remove("analyze_spm.mat")


def scl(header):
    """A header's slope and intercept (None: no valid scaling)."""
    s, i = header.get_slope_inter()
    return (None if s is None else float(s)), (None if i is None else float(i))


def units(header):
    try:
        return header.get_xyzt_units()
    except Exception:
        return ("unknown", "unknown")


def describe(name):
    img = nib.load(name)
    hdr = img.header
    shape = [int(s) for s in img.shape]
    dtype = hdr.get_data_dtype()
    a = img.affine
    # nibabel moves the scaling of a loaded image into its array proxy (the header's scl
    # fields then read NaN); slope 1, intercept 0 when the file has none.
    slope, inter = float(img.dataobj.slope), float(img.dataobj.inter)
    space, time = units(hdr)
    stored = np.asanyarray(img.dataobj.get_unscaled())
    scaled = np.asanyarray(img.dataobj)
    nd = len(shape)
    rng = np.random.default_rng(7)
    picks = [tuple([0] * nd), tuple(s - 1 for s in shape), tuple(s // 2 for s in shape)]
    picks += [tuple(int(rng.integers(0, s)) for s in shape) for _ in range(5)]
    voxels = [
        {"index": [int(x) for x in p], "stored": float(stored[p]), "value": float(scaled[p])}
        for p in picks
    ]
    corners = []
    for c in range(8):
        ijk = [0 if (c >> ax) & 1 == 0 else shape[ax] - 1 for ax in range(3)]
        w = a @ np.array(ijk + [1.0])
        corners.append({"index": ijk, "world": [float(x) for x in w[:3]]})
    pixdim = [float(x) for x in hdr["pixdim"]]
    return {
        "file": name,
        "class": type(img).__name__,
        "shape": shape,
        "dtype": dtype.name,
        "byteorder": "big" if dtype.byteorder == ">" or (dtype.byteorder == "=" and np.little_endian is False) else "little",
        "affine": [[float(x) for x in row] for row in a[:3]],
        "space_unit": space,
        "time_unit": time,
        "scl_slope": slope,
        "scl_inter": inter,
        "pixdim4": pixdim[4] if len(pixdim) > 4 else None,
        "toffset": float(hdr["toffset"]) if "toffset" in hdr else 0.0,
        "voxels": voxels,
        "corners": corners,
        "min": float(np.nanmin(scaled)),
        "max": float(np.nanmax(scaled)),
    }


def describe_header(name, klass):
    with open(name, "rb") as f:
        hdr = klass.from_fileobj(f)
    slope, inter = scl(hdr)
    shape = [int(s) for s in hdr.get_data_shape()]
    return {
        "file": name,
        "class": klass.__name__,
        "header_only": True,
        "shape": shape,
        "dtype": hdr.get_data_dtype().name,
        "affine": [[float(x) for x in row] for row in hdr.get_best_affine()[:3]],
        "scl_slope": slope,
        "scl_inter": inter,
        "vox_offset": float(hdr["vox_offset"]),
    }


def main():
    os.chdir(HERE)
    for name in COPIED:
        shutil.copyfile(os.path.join(NIB_DATA, name), name)
    write_generated()
    files = [
        "anatomical.nii",
        "functional.nii",
        "example4d.nii.gz",
        "example_nifti2.nii.gz",
        "big_endian.nii",
        "scaled_i16.nii",
        "qform_qfac.nii",
        "sform_oblique.nii",
        "pair.hdr",
        "pair_gz.img.gz",
        "f64.nii.gz",
        "u16.nii",
        "nifti2_be_4d.nii",
        "analyze_spm.hdr",
    ]
    # Physical values of scaled_i16.nii along x on the four rows around (y, z) = (5.25, 4.5):
    # the crossing of an isovalue there is what `render --iso` must hit (the app test).
    scaled = np.asanyarray(nib.load("scaled_i16.nii").dataobj)
    profiles = [
        {"file": "scaled_i16.nii", "j": j, "k": k, "values": [float(x) for x in scaled[:, j, k]]}
        for k in (4, 5)
        for j in (5, 6)
    ]
    out = {
        "nibabel": nib.__version__,
        "numpy": np.__version__,
        "files": [describe(f) for f in files],
        "headers": [
            describe_header("analyze.hdr", nib.Spm2AnalyzeHeader),
            describe_header("nifti1.hdr", nib.Nifti1Header),
            describe_header("nifti2.hdr", nib.Nifti2Header),
        ],
        "profiles": profiles,
    }
    with open("expected.json", "w") as f:
        json.dump(out, f, indent=1)
        f.write("\n")


if __name__ == "__main__":
    main()
