#!/usr/bin/env python3
"""Writes a CT-like DICOM series with pydicom, for the open-speed benchmark
(docs/benchmarks.md, "Opening DICOM"): one file per slice, explicit VR little endian, int16
stored values with RescaleIntercept -1024 (Hounsfield units), 0.7 mm pixels, 1.25 mm slices,
positions in LPS as scanners write them.

    python make_dicom_ct.py OUT_DIR [--size 512] [--slices 300]

The volume is a head-sized ellipsoid: skin, a skull shell 5–12 mm deep, brain, edges
blurred over about a millimetre, noise σ 20 HU; bone is an isosurface at 300–600 HU, skin
at -300 HU. Independent of Isoscope: numpy and pydicom only."""
import argparse
import os

import numpy as np
import pydicom
from pydicom.dataset import FileDataset, FileMetaDataset
from pydicom.uid import CTImageStorage, ExplicitVRLittleEndian, generate_uid


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--slices", type=int, default=300)
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    n, nz = a.size, a.slices
    px, dz = 0.7, 1.25
    rng = np.random.default_rng(7)
    y, x = np.mgrid[0:n, 0:n].astype(np.float32)
    cx = cy = (n - 1) / 2
    study, series, frame = generate_uid(), generate_uid(), generate_uid()
    for k in range(nz):
        z = (k - nz / 2) * dz
        # Ellipsoid radii in mm (head: 80 x 95 x 110); depth below the skin in mm along
        # the normalised radius. Soft tissue 40 HU, a skull from 5 to 12 mm deep (1200 HU),
        # brain 30 HU; edges blurred over about a millimetre (partial volume), as a scanner's
        # point spread does, so the surfaces are smooth and not voxel terraces.
        rx, ry, rz = 80.0, 95.0, 110.0
        r = np.sqrt(((x - cx) * px / rx) ** 2 + ((y - cy) * px / ry) ** 2 + (z / rz) ** 2)
        depth = (1.0 - r) * 90.0

        def step(d):
            return 1.0 / (1.0 + np.exp(np.clip(-d / 0.6, -60.0, 60.0)))

        hu = -1000.0 + 1040.0 * step(depth)
        skull = step(depth - 5.0) * step(12.0 - depth)
        hu += 1160.0 * skull
        hu += -10.0 * step(depth - 12.0)
        hu += rng.normal(0.0, 20.0, hu.shape).astype(np.float32)
        stored = np.clip(np.round(hu + 1024.0), -32768, 32767).astype(np.int16)

        meta = FileMetaDataset()
        meta.MediaStorageSOPClassUID = CTImageStorage
        meta.MediaStorageSOPInstanceUID = generate_uid()
        meta.TransferSyntaxUID = ExplicitVRLittleEndian
        path = os.path.join(a.out, f"IM{k:04d}.dcm")
        ds = FileDataset(path, {}, file_meta=meta, preamble=b"\0" * 128)
        ds.SOPClassUID = CTImageStorage
        ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
        ds.StudyInstanceUID, ds.SeriesInstanceUID, ds.FrameOfReferenceUID = study, series, frame
        ds.Modality = "CT"
        ds.SeriesDescription = "synthetic head CT"
        ds.SeriesNumber = 1
        ds.InstanceNumber = k + 1
        ds.PatientName = "Phantom^Head"
        ds.PatientID = "0"
        ds.ImagePositionPatient = [-cx * px, -cy * px, z]
        ds.ImageOrientationPatient = [1, 0, 0, 0, 1, 0]
        ds.PixelSpacing = [px, px]
        ds.SliceThickness = dz
        ds.Rows, ds.Columns = n, n
        ds.SamplesPerPixel = 1
        ds.PhotometricInterpretation = "MONOCHROME2"
        ds.BitsAllocated, ds.BitsStored, ds.HighBit = 16, 16, 15
        ds.PixelRepresentation = 1
        ds.RescaleIntercept, ds.RescaleSlope = -1024, 1
        ds.PixelData = stored.tobytes()
        ds.save_as(path, enforce_file_format=True)


if __name__ == "__main__":
    main()
