#!/usr/bin/env python3
"""Writes the DICOM test fixtures of formats/tests/dicom.rs and what other programs report
about them (truth.json).

Run from this folder with the peers venv (pydicom 3, numpy, SimpleITK, Pillow):

    /work/venvs/peers/bin/python make_dicom.py

- real/: files copied from pydicom's own test data (see README.md);
- synthetic/<case>/: series written here with pydicom (and SimpleITK/GDCM for JPEG lossless
  and JPEG 2000 lossless, Pillow for JPEG baseline);
- truth.json: per case, what pydicom + numpy report: dims (columns, rows, slices), dtype,
  stored values (x fastest, then rows, then slices ordered along the slice normal), rescale,
  and the LPS position of the 8 corner voxels computed from each slice's own
  ImagePositionPatient, ImageOrientationPatient and PixelSpacing; or the error expected.

Everything is deterministic (fixed UIDs, fixed shuffles), so re-running rewrites the same
bytes (up to pydicom/GDCM version differences).
"""

import io
import json
import os
import random
import shutil

import numpy as np
import pydicom
import SimpleITK as sitk
from PIL import Image
from pydicom.dataset import Dataset, FileMetaDataset
from pydicom.encaps import encapsulate
from pydicom.uid import (
    CTImageStorage,
    EnhancedCTImageStorage,
    ExplicitVRLittleEndian,
    JPEGBaseline8Bit,
    MRImageStorage,
    generate_uid,
)

HERE = os.path.dirname(os.path.abspath(__file__))
PYDICOM_DATA = os.path.join(os.path.dirname(pydicom.__file__), "data", "test_files")
ROOT = "1.2.826.0.1.3680043.8.498."  # pydicom's UID root


def uid(name):
    return generate_uid(prefix=ROOT, entropy_srcs=["isoscope-dicom-fixtures", name])


def fmt_ds(x):
    return f"{x:.6f}".rstrip("0").rstrip(".") if abs(x) >= 1e-6 else "0"


def blob(cols, rows, n, scale=1000.0):
    """A smooth blob (values fall off from the centre), shape (n, rows, cols)."""
    z, y, x = np.meshgrid(
        np.linspace(-1, 1, n), np.linspace(-1, 1, rows), np.linspace(-1, 1, cols), indexing="ij"
    )
    return scale * np.exp(-2.0 * (x * x + 1.3 * y * y + 0.8 * z * z))


def image_dataset(sop_class, series, instance, arr, *, modality="CT", description=""):
    """A single-frame image data set (explicit VR little endian) for `arr` (rows, cols)."""
    ds = Dataset()
    ds.file_meta = FileMetaDataset()
    ds.file_meta.MediaStorageSOPClassUID = sop_class
    ds.file_meta.MediaStorageSOPInstanceUID = uid(f"{series}/{instance}")
    ds.file_meta.TransferSyntaxUID = ExplicitVRLittleEndian
    ds.SOPClassUID = sop_class
    ds.SOPInstanceUID = ds.file_meta.MediaStorageSOPInstanceUID
    ds.StudyInstanceUID = uid("study")
    ds.SeriesInstanceUID = uid(series)
    ds.FrameOfReferenceUID = uid("frame")
    ds.Modality = modality
    ds.SeriesDescription = description or series
    ds.PatientName = "Phantom^Isoscope"
    ds.PatientID = "ISO-0"
    ds.SamplesPerPixel = 1
    ds.PhotometricInterpretation = "MONOCHROME2"
    ds.Rows, ds.Columns = arr.shape
    signed = arr.dtype.kind == "i"
    bits = arr.dtype.itemsize * 8
    ds.BitsAllocated = bits
    ds.BitsStored = bits
    ds.HighBit = bits - 1
    ds.PixelRepresentation = 1 if signed else 0
    ds.PixelData = arr.astype(arr.dtype.newbyteorder("<")).tobytes()
    return ds


def place(ds, ipp, iop, spacing):
    ds.ImagePositionPatient = [fmt_ds(v) for v in ipp]
    ds.ImageOrientationPatient = [fmt_ds(v) for v in iop]
    ds.PixelSpacing = [fmt_ds(v) for v in spacing]
    ds.SliceThickness = "99"  # deliberately wrong: spacing must come from the positions


def save(ds, path):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    ds.save_as(path, enforce_file_format=True)


def rotation(ax, ay, az):
    """Row and column direction cosines of an oblique plane."""
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    m = rz @ ry @ rx
    return list(m[:, 0]) + list(m[:, 1])


def truth_of(paths, pick=None):
    """What pydicom + numpy report about the series in `paths` (single-frame files)."""
    sl = [pydicom.dcmread(p) for p in paths]
    if pick is not None:
        sl = [d for d in sl if d.SeriesInstanceUID == pick]
    iop = np.array([float(v) for v in sl[0].ImageOrientationPatient])
    row, col = iop[:3], iop[3:]
    normal = np.cross(row, col)
    sl.sort(key=lambda d: float(np.dot([float(v) for v in d.ImagePositionPatient], normal)))
    return truth_from_frames(
        [(d, d.pixel_array, [float(v) for v in d.ImagePositionPatient]) for d in sl], row, col
    )


def truth_from_frames(frames, row, col):
    """frames: (dataset holding spacing/rescale, 2D array, IPP), sorted along the normal."""
    d0 = frames[0][0]
    # [row spacing (Δy), column spacing (Δx)]; a single image without it has unit pixels.
    ps = [float(v) for v in getattr(d0, "PixelSpacing", None) or [1, 1]]
    rows, cols = frames[0][1].shape
    vol = np.stack([f[1] for f in frames])  # (k, j, i)
    corners = []
    for k in (0, len(frames) - 1):
        for j in (0, rows - 1):
            for i in (0, cols - 1):
                p = np.array(frames[k][2]) + i * ps[1] * np.array(row) + j * ps[0] * np.array(col)
                corners.append({"ijk": [i, j, k], "lps": [float(v) for v in p]})
    slope = float(getattr(d0, "RescaleSlope", 1) or 1)
    intercept = float(getattr(d0, "RescaleIntercept", 0) or 0)
    flat = [float(v) for v in vol.ravel()]
    values = {"voxels": flat}
    if len(flat) > 20000:
        # Large images: every 61st voxel, and the sum, minimum and maximum of all.
        values = {"voxel_stride": 61, "voxels_sampled": flat[::61], "sum": float(sum(flat)),
                  "min": min(flat), "max": max(flat)}
    return {
        "dims": [cols, rows, len(frames)],
        "dtype": {"int16": "i16", "uint16": "u16", "uint8": "u8", "int8": "i8", "uint32": "u32",
                  "int32": "i32", "float32": "f32", "float64": "f64"}[str(vol.dtype)],
        "slope": slope,
        "intercept": intercept,
        **values,
        "corners": corners,
    }


TRUTH = {}


def case(name, **entry):
    TRUTH[name] = entry


def synthetic():
    out = os.path.join(HERE, "synthetic")
    shutil.rmtree(out, ignore_errors=True)
    rng = random.Random(7)

    # 1. Oblique series, shuffled file names and InstanceNumbers, rescale, cols != rows,
    #    PixelSpacing [row spacing 0.7, column spacing 0.4].
    cols, rows, n = 12, 10, 6
    vol = blob(cols, rows, n).astype(np.int16)
    iop = rotation(0.3, -0.2, 0.5)
    row, col = np.array(iop[:3]), np.array(iop[3:])
    normal = np.cross(row, col)
    origin = np.array([-20.5, 13.25, 40.0])
    order = list(range(n))
    rng.shuffle(order)
    names = [f"IMG{rng.randrange(10000):05d}.dcm" for _ in range(n)]
    paths = []
    for k in range(n):
        ds = image_dataset(CTImageStorage, "oblique", k, vol[k])
        place(ds, origin + 1.5 * k * normal, iop, [0.7, 0.4])
        ds.InstanceNumber = order[k] + 1
        ds.RescaleSlope = "2"
        ds.RescaleIntercept = "-100"
        p = os.path.join(out, "oblique", names[k])
        save(ds, p)
        paths.append(p)
    case("oblique", path="synthetic/oblique", **truth_of(paths), uniform=True)

    # 2. Slightly uneven spacing (axial): explicit z coordinates.
    cols, rows = 8, 7
    zs = [0.0, 1.0, 2.1, 3.0, 4.2]
    vol = blob(cols, rows, len(zs)).astype(np.int16)
    paths = []
    for k, z in enumerate(zs):
        ds = image_dataset(CTImageStorage, "uneven", k, vol[k])
        place(ds, [5.0, -3.0, z], [1, 0, 0, 0, 1, 0], [0.5, 0.25])
        p = os.path.join(out, "uneven", f"s{len(zs) - k}.dcm")
        save(ds, p)
        paths.append(p)
    case("uneven", path="synthetic/uneven", **truth_of(paths), uniform=False)

    # 3. A missing slice: positions 0, 2, 4, 8, 10.
    paths = []
    for k, z in enumerate([0.0, 2.0, 4.0, 8.0, 10.0]):
        ds = image_dataset(CTImageStorage, "gap", k, np.zeros((4, 4), np.int16))
        place(ds, [0, 0, z], [1, 0, 0, 0, 1, 0], [1, 1])
        save(ds, os.path.join(out, "gap", f"g{k}.dcm"))
    case("gap", path="synthetic/gap", error="missing slices", error_also=["4.000", "8.000"])

    # 4. Gantry tilt: positions drift in y along the stack (axial orientation).
    cols, rows, n = 9, 8, 5
    vol = blob(cols, rows, n).astype(np.int16)
    paths = []
    for k in range(n):
        ds = image_dataset(CTImageStorage, "tilt", k, vol[k])
        place(ds, [-4.0, 2.0 + 0.35 * k, -10.0 + 2.0 * k], [1, 0, 0, 0, 1, 0], [0.6, 0.6])
        p = os.path.join(out, "tilt", f"t{k}.dcm")
        save(ds, p)
        paths.append(p)
    case("tilt", path="synthetic/tilt", **truth_of(paths), uniform=True)

    # 5. Two series in one folder, plus a structured report and a text file (skipped).
    two = os.path.join(out, "two_series")
    ct = blob(6, 5, 4).astype(np.int16)
    for k in range(4):
        ds = image_dataset(CTImageStorage, "two/ct", k, ct[k], description="CT head")
        ds.SeriesNumber = 2
        place(ds, [0, 0, 3.0 * k], [1, 0, 0, 0, 1, 0], [0.8, 0.8])
        save(ds, os.path.join(two, "ct", f"c{k}.dcm"))
    mr = blob(5, 5, 3, 300).astype(np.uint16)
    mr_paths = []
    for k in range(3):
        ds = image_dataset(MRImageStorage, "two/mr", k, mr[k], modality="MR", description="MR T1")
        ds.SeriesNumber = 5
        place(ds, [2.0 * k, 0, 0], [0, 1, 0, 0, 0, -1], [1.0, 1.0])
        p = os.path.join(two, "mr", f"m{k}.dcm")
        save(ds, p)
        mr_paths.append(p)
    sr = Dataset()
    sr.file_meta = FileMetaDataset()
    sr.file_meta.MediaStorageSOPClassUID = "1.2.840.10008.5.1.4.1.1.88.11"  # Basic Text SR
    sr.file_meta.MediaStorageSOPInstanceUID = uid("sr")
    sr.file_meta.TransferSyntaxUID = ExplicitVRLittleEndian
    sr.SOPClassUID = sr.file_meta.MediaStorageSOPClassUID
    sr.SOPInstanceUID = uid("sr")
    sr.Modality = "SR"
    sr.SeriesInstanceUID = uid("two/sr")
    save(sr, os.path.join(two, "report.dcm"))
    with open(os.path.join(two, "README.txt"), "w") as f:
        f.write("not DICOM\n")
    mr_truth = truth_of(mr_paths)
    case(
        "two_series",
        path="synthetic/two_series",
        error="2 series in",
        series=[
            {"uid": uid("two/ct"), "modality": "CT", "description": "CT head", "number": 2,
             "dims": [6, 5, 4], "files": 4},
            {"uid": uid("two/mr"), "modality": "MR", "description": "MR T1", "number": 5,
             "dims": [5, 5, 3], "files": 3},
        ],
        skipped=["report.dcm", "README.txt"],
    )
    case("two_series_mr", path="synthetic/two_series", pick="2", **mr_truth, uniform=True)
    case("two_series_mr_uid", path="synthetic/two_series", pick=uid("two/mr"), **mr_truth,
         uniform=True)

    # 6. Enhanced multi-frame CT: per-frame positions (stored in reverse order), shared
    #    orientation, spacing and rescale.
    cols, rows, n = 7, 6, 4
    vol = blob(cols, rows, n).astype(np.int16)
    iop = [0, 1, 0, 0, 0, -1]  # sagittal
    row, col = np.array(iop[:3], float), np.array(iop[3:], float)
    normal = np.cross(row, col)
    ds = image_dataset(EnhancedCTImageStorage, "multiframe", 0, vol[0])
    ds.NumberOfFrames = n
    stored = list(reversed(range(n)))  # frame f holds slice stored[f]
    ds.PixelData = np.stack([vol[k] for k in stored]).astype("<i2").tobytes()
    shared = Dataset()
    pm = Dataset()
    pm.PixelSpacing = ["0.9", "0.45"]
    pm.SliceThickness = "99"
    po = Dataset()
    po.ImageOrientationPatient = [fmt_ds(v) for v in iop]
    pvt = Dataset()
    pvt.RescaleSlope = "1"
    pvt.RescaleIntercept = "-1024"
    pvt.RescaleType = "HU"
    shared.PixelMeasuresSequence = [pm]
    shared.PlaneOrientationSequence = [po]
    shared.PixelValueTransformationSequence = [pvt]
    ds.SharedFunctionalGroupsSequence = [shared]
    per = []
    ipps = {}
    for f, k in enumerate(stored):
        item = Dataset()
        pp = Dataset()
        ipp = np.array([12.0, -7.5, 30.0]) + 2.5 * k * normal
        ipps[k] = [float(fmt_ds(v)) for v in ipp]
        pp.ImagePositionPatient = [fmt_ds(v) for v in ipp]
        item.PlanePositionSequence = [pp]
        fc = Dataset()
        fc.InStackPositionNumber = f + 1
        item.FrameContentSequence = [fc]
        per.append(item)
    ds.PerFrameFunctionalGroupsSequence = per
    p = os.path.join(out, "multiframe", "enhanced.dcm")
    save(ds, p)
    d = pydicom.dcmread(p)
    arr = d.pixel_array
    frames = []
    for f, k in sorted(enumerate(stored), key=lambda fk: fk[1]):
        frames.append((d.SharedFunctionalGroupsSequence[0].PixelMeasuresSequence[0], arr[f], ipps[k]))
    t = truth_from_frames(frames, row, col)
    t["slope"], t["intercept"] = 1.0, -1024.0
    case("multiframe", path="synthetic/multiframe/enhanced.dcm", **t, uniform=True)

    # 7. Different rescales per slice: f32 physical values.
    vol = blob(5, 4, 3).astype(np.int16)
    paths = []
    for k in range(3):
        ds = image_dataset(CTImageStorage, "rescale_mixed", k, vol[k])
        place(ds, [0, 0, float(k)], [1, 0, 0, 0, 1, 0], [1, 1])
        ds.RescaleSlope = ["1", "0.5", "2"][k]
        ds.RescaleIntercept = ["0", "10", "-1000"][k]
        p = os.path.join(out, "rescale_mixed", f"r{k}.dcm")
        save(ds, p)
        paths.append(p)
    t = truth_of(paths)
    phys = []
    per_slice = 5 * 4
    for k, p in enumerate(paths):
        d = pydicom.dcmread(p)
        phys += [float(v) * float(d.RescaleSlope) + float(d.RescaleIntercept)
                 for v in d.pixel_array.ravel()]
    t.update(dtype="f32", slope=1.0, intercept=0.0, voxels=phys)
    assert len(phys) == 3 * per_slice
    case("rescale_mixed", path="synthetic/rescale_mixed", **t, uniform=True)

    # 8. Duplicate positions.
    for k, z in enumerate([0.0, 1.0, 1.0, 2.0]):
        ds = image_dataset(CTImageStorage, "duplicates", k, np.zeros((3, 3), np.int16))
        place(ds, [0, 0, z], [1, 0, 0, 0, 1, 0], [1, 1])
        save(ds, os.path.join(out, "duplicates", f"d{k}.dcm"))
    case("duplicates", path="synthetic/duplicates", error="duplicate slices",
         error_also=["d1.dcm", "d2.dcm"])

    # 9. Two phases at three positions (TemporalPositionIdentifier): a time series.
    vol = blob(4, 4, 3).astype(np.int16)
    for t_id in (1, 2):
        for k in range(3):
            ds = image_dataset(MRImageStorage, "phases", 10 * t_id + k, vol[k] + 100 * t_id, modality="MR")
            place(ds, [0, 0, 2.0 * k], [1, 0, 0, 0, 1, 0], [1, 1])
            ds.TemporalPositionIdentifier = t_id
            ds.NumberOfTemporalPositions = 2
            save(ds, os.path.join(out, "phases", f"p{(t_id * 7 + k * 3) % 10}{t_id}{k}.dcm"))
    case("phases", path="synthetic/phases", phases=2, dims=[4, 4, 3],
         phase_voxels=[[float(v) for v in (vol + 100 * t_id).ravel()] for t_id in (1, 2)])

    # 10. 12 bits stored in 16 with other bits set (unsigned): the values are the low 12 bits.
    raw = (np.arange(16, dtype=np.uint16).reshape(4, 4) * 257) | 0xF000
    paths = []
    for k in range(2):
        ds = image_dataset(CTImageStorage, "bits12", k, raw + k)
        ds.BitsStored = 12
        ds.HighBit = 11
        place(ds, [0, 0, float(k)], [1, 0, 0, 0, 1, 0], [1, 1])
        p = os.path.join(out, "bits12", f"b{k}.dcm")
        save(ds, p)
        paths.append(p)
    case("bits12", path="synthetic/bits12", **truth_of(paths), uniform=True)

    # 11. One UID, two image sizes: split into two parts.
    for k in range(3):
        size = (4, 4) if k < 2 else (5, 4)
        ds = image_dataset(CTImageStorage, "split", k, np.zeros(size, np.int16))
        place(ds, [0, 0, float(k)], [1, 0, 0, 0, 1, 0], [1, 1])
        save(ds, os.path.join(out, "split", f"x{k}.dcm"))
    case("split", path="synthetic/split", pick=uid("split"), error="split into 2 parts")

    # 12. JPEG lossless (process 14 SV1) and JPEG 2000 lossless slices written by
    #     SimpleITK/GDCM, then placed with pydicom (the compressed pixel data is kept).
    vol = (blob(10, 9, 3, 3000) - 800).astype(np.int16)
    for comp, label in (("JPEG", "jpeg_lossless"), ("JPEG2000", "j2k_lossless")):
        paths = []
        for k in range(3):
            tmp = os.path.join(out, f"_{label}{k}.dcm")
            os.makedirs(out, exist_ok=True)
            w = sitk.ImageFileWriter()
            w.SetFileName(tmp)
            w.SetUseCompression(True)
            w.SetCompressor(comp)
            w.Execute(sitk.GetImageFromArray(vol[k]))
            d = pydicom.dcmread(tmp)
            os.remove(tmp)
            d.SeriesInstanceUID = uid(label)
            d.Modality = "CT"
            place(d, [1.0, 2.0, 3.0 + 1.25 * k], [1, 0, 0, 0, 1, 0], [0.5, 0.5])
            p = os.path.join(out, label, f"{label}{k}.dcm")
            save(d, p)
            paths.append(p)
        t = truth_from_frames(
            [(pydicom.dcmread(p), sitk.GetArrayFromImage(sitk.ReadImage(p))[0],
              [1.0, 2.0, 3.0 + 1.25 * k]) for k, p in enumerate(paths)],
            [1, 0, 0], [0, 1, 0])
        assert t["voxels"] == [float(v) for v in vol.ravel()], label
        ts = pydicom.dcmread(paths[0]).file_meta.TransferSyntaxUID
        case(label, path=f"synthetic/{label}", **t, uniform=True, transfer_syntax=str(ts))

    # 13. JPEG baseline (8-bit, lossy) written by Pillow; pydicom (Pillow) decodes it.
    img = np.clip(blob(16, 16, 1, 250)[0], 0, 255).astype(np.uint8)
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="JPEG", quality=90)
    ds = image_dataset(CTImageStorage, "jpeg_baseline", 0, img)
    ds.file_meta.TransferSyntaxUID = JPEGBaseline8Bit
    ds.PixelData = encapsulate([buf.getvalue()])
    ds["PixelData"].VR = "OB"
    place(ds, [0, 0, 0], [1, 0, 0, 0, 1, 0], [1, 1])
    p = os.path.join(out, "jpeg_baseline", "baseline.dcm")
    save(ds, p)
    ds = pydicom.dcmread(p)
    t = truth_from_frames([(ds, ds.pixel_array, [0, 0, 0])], [1, 0, 0], [0, 1, 0])
    case("jpeg_baseline", path="synthetic/jpeg_baseline/baseline.dcm", **t, uniform=True,
         tolerance=2)

    # 14. The NRRD twin: oblique, no rescale, u16.
    cols, rows, n = 14, 12, 10
    vol = blob(cols, rows, n, 1000).astype(np.uint16)
    iop = rotation(-0.25, 0.15, 0.35)
    row, col = np.array(iop[:3]), np.array(iop[3:])
    normal = np.cross(row, col)
    paths = []
    for k in range(n):
        ds = image_dataset(CTImageStorage, "twin", k, vol[k])
        place(ds, np.array([3.0, -2.0, 5.0]) + 0.9 * k * normal, iop, [0.8, 0.6])
        p = os.path.join(out, "twin", f"tw{(k * 7) % n:02d}.dcm")
        save(ds, p)
        paths.append(p)
    t = truth_of(paths)
    ds = pydicom.dcmread(paths[0])
    r = [float(v) for v in ds.ImageOrientationPatient]
    t["world_from_grid"] = {
        "columns": [r[:3], r[3:], [float(v) for v in np.cross(r[:3], r[3:])]],
        "origin": [float(v) for v in ds.ImagePositionPatient],
        "spacing": [0.6, 0.8, 0.9],
    }
    case("twin", path="synthetic/twin", **t, uniform=True)


def bad():
    """Broken inputs: each a folder (or file) and the error text expected."""
    out = os.path.join(HERE, "bad")
    shutil.rmtree(out, ignore_errors=True)
    os.makedirs(out)
    good = image_dataset(CTImageStorage, "bad", 0, np.arange(16, dtype=np.int16).reshape(4, 4))
    place(good, [0, 0, 0], [1, 0, 0, 0, 1, 0], [1, 1])
    # Each case in its own folder: one file opens its folder's series.
    buf = io.BytesIO()
    good.save_as(buf, enforce_file_format=True)
    data = buf.getvalue()
    os.makedirs(os.path.join(out, "truncated"))
    with open(os.path.join(out, "truncated", "truncated.dcm"), "wb") as f:
        f.write(data[: len(data) - 9])
    case("truncated", path="bad/truncated/truncated.dcm", error="claims 32 bytes but only 23 remain",
         error_also=["truncated.dcm"])
    # Pixel data shorter than Rows × Columns (the element itself is complete).
    short = image_dataset(CTImageStorage, "bad", 1, np.arange(16, dtype=np.int16).reshape(4, 4))
    place(short, [0, 0, 0], [1, 0, 0, 0, 1, 0], [1, 1])
    short.PixelData = short.PixelData[:20]
    save(short, os.path.join(out, "short_pixels", "short_pixels.dcm"))
    case("short_pixels", path="bad/short_pixels/short_pixels.dcm", error="data needs 32 bytes",
         error_also=["short_pixels.dcm"])
    # Unknown transfer syntax (encapsulated).
    unk = image_dataset(CTImageStorage, "bad", 2, np.zeros((4, 4), np.int16))
    place(unk, [0, 0, 0], [1, 0, 0, 0, 1, 0], [1, 1])
    unk.file_meta.TransferSyntaxUID = "1.2.840.10008.1.2.4.80"  # JPEG-LS lossless
    unk.PixelData = encapsulate([b"\xff\xd8" + b"\0" * 30])
    unk["PixelData"].VR = "OB"
    save(unk, os.path.join(out, "jpeg_ls", "jpeg_ls.dcm"))
    case("jpeg_ls", path="bad/jpeg_ls/jpeg_ls.dcm",
         error="1.2.840.10008.1.2.4.80 (JPEG-LS Lossless Image Compression)",
         error_also=["jpeg_ls.dcm"])
    unk.file_meta.TransferSyntaxUID = "1.2.3.4.5.6.7"
    os.makedirs(os.path.join(out, "private_syntax"))
    unk.save_as(os.path.join(out, "private_syntax", "private_syntax.dcm"),
                enforce_file_format=True, implicit_vr=False, little_endian=True)
    case("private_syntax", path="bad/private_syntax/private_syntax.dcm",
         error="1.2.3.4.5.6.7 (unknown transfer syntax)", error_also=["private_syntax.dcm"])
    # Slices of different sizes with one SeriesInstanceUID are two parts (listed); their
    # UID is ambiguous: see synthetic/split. A DICOMDIR pointing at a missing file:
    from pydicom.fileset import FileSet

    fs_dir = os.path.join(out, "dicomdir_missing")
    os.makedirs(fs_dir)
    fs = FileSet()
    for k in range(2):
        ds = image_dataset(CTImageStorage, "fs", k, np.zeros((4, 4), np.int16))
        place(ds, [0, 0, float(k)], [1, 0, 0, 0, 1, 0], [1, 1])
        ds.PatientID = "ISO-0"
        ds.StudyDate = "20240101"
        ds.StudyTime = "000000"
        ds.StudyID = "1"
        ds.AccessionNumber = ""
        ds.SeriesNumber = 1
        ds.InstanceNumber = k + 1
        fs.add(ds)
    fs.write(fs_dir)
    victim = None
    for root, _, files in os.walk(fs_dir):
        for name in sorted(files):
            if name != "DICOMDIR":
                victim = os.path.join(root, name)
    os.remove(victim)
    case("dicomdir_missing", path="bad/dicomdir_missing/DICOMDIR", error="which does not exist",
         error_also=[os.path.basename(victim)])


def real():
    """Files copied from pydicom's test data, with what pydicom (or SimpleITK/GDCM, for
    syntaxes pydicom cannot decode here) reports."""
    out = os.path.join(HERE, "real")
    shutil.rmtree(out, ignore_errors=True)
    os.makedirs(out)
    single = {
        "CT_small.dcm": "pydicom",
        "MR_small.dcm": "pydicom",
        "MR_small_implicit.dcm": "pydicom",
        "MR_small_bigendian.dcm": "pydicom",
        "MR_small_RLE.dcm": "pydicom",
        "MR_small_jp2klossless.dcm": "pydicom",
        "image_dfl.dcm": "pydicom",
        "693_J2KI.dcm": "pydicom",
        "JPEG2000.dcm": "pydicom",
    }
    for name, reader in single.items():
        d = os.path.join(out, name[:-4])
        os.makedirs(d)
        shutil.copy(os.path.join(PYDICOM_DATA, name), d)
        p = os.path.join(d, name)
        ds = pydicom.dcmread(p)
        # A single image without a position or orientation sits at the origin, axis-aligned.
        ipp = [float(v) for v in getattr(ds, "ImagePositionPatient", None) or [0, 0, 0]]
        iop = [float(v) for v in getattr(ds, "ImageOrientationPatient", None) or [1, 0, 0, 0, 1, 0]]
        t = truth_from_frames([(ds, ds.pixel_array, ipp)], iop[:3], iop[3:])
        lossy = name in ("693_J2KI.dcm", "JPEG2000.dcm")
        case("real/" + name, path=f"real/{name[:-4]}/{name}", **t, uniform=True,
             tolerance=1 if lossy else 0, reader=reader,
             transfer_syntax=str(ds.file_meta.TransferSyntaxUID))
    # RT Dose: 15 frames placed by GridFrameOffsetVector, dose = stored × DoseGridScaling.
    for name in ("rtdose.dcm", "rtdose_rle.dcm"):
        d = os.path.join(out, name[:-4])
        os.makedirs(d)
        shutil.copy(os.path.join(PYDICOM_DATA, name), d)
        ds = pydicom.dcmread(os.path.join(d, name))
        iop = [float(v) for v in ds.ImageOrientationPatient]
        normal = np.cross(iop[:3], iop[3:])
        ipp = np.array([float(v) for v in ds.ImagePositionPatient])
        g = [float(v) for v in ds.GridFrameOffsetVector]
        arr = ds.pixel_array
        frames = [(ds, arr[k], list(ipp + (g[k] - g[0]) * normal)) for k in range(len(g))]
        frames.sort(key=lambda f: float(np.dot(f[2], normal)))
        t = truth_from_frames(frames, iop[:3], iop[3:])
        t["slope"], t["intercept"] = float(ds.DoseGridScaling), 0.0
        case("real/" + name, path=f"real/{name[:-4]}/{name}", **t, uniform=True)
    # Truncated (pydicom's MR_truncated.dcm) and a structured report (skipped).
    for name in ("MR_truncated.dcm", "MR_small_jpeg_ls_lossless.dcm", "test-SR.dcm"):
        d = os.path.join(out, name[:-4])
        os.makedirs(d)
        shutil.copy(os.path.join(PYDICOM_DATA, name), d)
    case("real/MR_truncated.dcm", path="real/MR_truncated/MR_truncated.dcm",
         error="claims 8192 bytes but only 8130 remain", error_also=["MR_truncated.dcm"])
    case("real/MR_small_jpeg_ls_lossless.dcm",
         path="real/MR_small_jpeg_ls_lossless/MR_small_jpeg_ls_lossless.dcm",
         error="1.2.840.10008.1.2.4.80 (JPEG-LS Lossless Image Compression)")
    case("real/test-SR.dcm", path="real/test-SR/test-SR.dcm", error="no pixel data")
    # The DICOMDIR test set (dcmmkdir, DCMTK): its CT series of 5 slices, and a CT series
    # of 4 whose first slice lies 202.5 mm away (missing slices).
    src = os.path.join(PYDICOM_DATA, "dicomdirtests")
    dst = os.path.join(out, "dicomdirtests")
    shutil.copytree(src, dst, ignore=shutil.ignore_patterns("TINY_ALPHA", "*.txt"))
    fs_paths = []
    for root, _, files in os.walk(dst):
        for f in files:
            if not f.startswith("DICOMDIR"):
                fs_paths.append(os.path.join(root, f))
    all_ds = [pydicom.dcmread(p) for p in sorted(fs_paths)]
    series = {}
    for d in all_ds:
        series.setdefault(d.SeriesInstanceUID, []).append(d)
    ct5 = [os.path.join(dst, "98892001", "CT5N", f) for f in sorted(os.listdir(os.path.join(dst, "98892001", "CT5N")))]
    t = truth_of(ct5)
    ct5_uid = pydicom.dcmread(ct5[0]).SeriesInstanceUID
    for dd in ("DICOMDIR", "DICOMDIR-bigEnd", "DICOMDIR-implicit"):
        # Referenced files, as pydicom's FileSet reads them.
        fs = pydicom.fileset.FileSet(os.path.join(dst, dd))
        n_files = len([i for i in fs])
        case("real/" + dd, path=f"real/dicomdirtests/{dd}", pick=ct5_uid, **t, uniform=True,
             referenced_files=n_files, series_uids=sorted(series.keys()))
    ct2 = os.path.join(dst, "77654033", "CT2")
    case("real/CT2_gap", path=f"real/dicomdirtests/77654033/CT2/17136", error="missing slices",
         error_also=["202.500 mm", "17106"])


if __name__ == "__main__":
    synthetic()
    bad()
    real()
    meta = {
        "pydicom": pydicom.__version__,
        "numpy": np.__version__,
        "SimpleITK": sitk.Version_VersionString(),
        "Pillow": Image.__version__,
    }
    with open(os.path.join(HERE, "truth.json"), "w") as f:
        f.write('{"written_by": ' + json.dumps(meta) + ',\n "cases": {\n')
        f.write(",\n".join(f" {json.dumps(k)}: {json.dumps(v, separators=(',', ':'))}"
                           for k, v in TRUTH.items()))
        f.write("\n }\n}\n")
    print(f"{len(TRUTH)} cases")
