#!/usr/bin/env python3
"""Writes the hand-made fuzz seeds into seeds/<target>/ (run from formats/fuzz/seeds).

`ok_*` seeds are valid inputs that the corpus replay (formats/tests/fuzz_corpus.rs) requires
the reader to accept; `bad_*` seeds are hostile inputs that only must not panic. Mesh seeds
also come from formats/tests/data/mesh (copied by the replay test's list, not here). The
`.isot` seeds are written by `isoscope preprocess` (see isot_seeds() below); the NIfTI seeds
are the small nibabel-written files of formats/tests/data/nifti.
"""
import bz2, gzip, json, os, struct, subprocess, sys

HERE = os.path.dirname(os.path.abspath(__file__))


def put(target, name, data):
    d = os.path.join(HERE, target)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, name), "wb") as f:
        f.write(data if isinstance(data, bytes) else data.encode())


def nhdr(enc, extra="", sizes="3 2 2", typ="uchar", data_file=None):
    h = f"NRRD0004\ntype: {typ}\ndimension: {len(sizes.split())}\nsizes: {sizes}\n"
    h += f"encoding: {enc}\nspacings: {' 1' * len(sizes.split())}\n"
    if typ not in ("uchar", "signed char"):
        h += "endian: little\n"
    h += extra
    if data_file:
        h += f"data file: {data_file}\n"
    return h + "\n"


def nrrd_seeds():
    vox = bytes(range(12))
    put("nrrd_data", "ok_raw.nrrd", nhdr("raw") + vox.decode("latin1"))
    put("nrrd_data", "ok_raw_u16.nrrd",
        nhdr("raw", typ="ushort").encode() + struct.pack("<12H", *range(12)))
    put("nrrd_data", "ok_gzip.nrrd", nhdr("gzip").encode() + gzip.compress(vox))
    put("nrrd_data", "ok_bzip2.nrrd", nhdr("bzip2").encode() + bz2.compress(vox))
    put("nrrd_data", "ok_ascii.nrrd", nhdr("ascii") + " ".join(map(str, vox)) + "\n")
    put("nrrd_data", "ok_hex.nrrd", nhdr("hex") + vox.hex() + "\n")
    put("nrrd_data", "ok_float_ascii.nrrd",
        nhdr("ascii", typ="float") + " ".join(str(i * 0.5) for i in range(12)))
    put("nrrd_data", "ok_skips.nrrd",
        nhdr("raw", "line skip: 1\nbyte skip: 3\n").encode() + b"junk line\nabc" + vox)
    put("nrrd_data", "ok_byteskip_end.nrrd", nhdr("raw", "byte skip: -1\n").encode() + b"xx" + vox)
    put("nrrd_data", "ok_detached.nhdr", nhdr("raw", data_file="d.raw").encode() + vox)
    put("nrrd_data", "ok_detached_gzip.nhdr",
        nhdr("gzip", data_file="d.raw.gz").encode() + gzip.compress(vox))
    put("nrrd_data", "ok_list.nhdr",
        (nhdr("raw", sizes="3 2 2 2", data_file="LIST 3")[:-1] + "d0.raw\nd1.raw\n\n").encode()
        + vox + vox[::-1])
    put("nrrd_data", "ok_pattern.nhdr",
        nhdr("raw", sizes="3 2 2 3", extra="kinds: space space space time\n",
             data_file="d%02d.raw 0 2 1 3").encode() + vox * 3)
    put("nrrd_data", "ok_4d_time.nrrd",
        nhdr("raw", sizes="3 2 2 2", extra="kinds: space space space time\n").encode() + vox * 2)
    put("nrrd_data", "bad_gzip_bomb.nrrd", nhdr("gzip").encode() + gzip.compress(bytes(1 << 16)))
    put("nrrd_data", "bad_short.nrrd", nhdr("raw") + "abc")


def raw_seeds():
    def layout(**kw):
        d = {"dims": [3, 2, 2], "type": "u8", "endian": "little", "spacing": [1, 1, 1]}
        d.update(kw)
        return json.dumps(d).encode() + b"\0"
    put("raw_sidecar", "ok_u8.json", layout() + bytes(range(12)))
    put("raw_sidecar", "ok_i16_big.json",
        layout(type="i16", endian="big", origin=[1, 2, 3]) + struct.pack(">12h", *range(-6, 6)))
    put("raw_sidecar", "ok_f32_header.json",
        layout(type="f32", header_bytes=5) + b"HEAD!" + struct.pack("<12f", *range(12)))
    put("raw_sidecar", "ok_f64.json", layout(type="f64", dims=[1, 1, 2]) + struct.pack("<2d", 1, 2))
    put("raw_sidecar", "bad_huge_dims.json",
        layout(dims=[1 << 40, 1 << 40, 1 << 40]) + b"x")


def tetgen_seeds(mesh_dir):
    for stem in ("tetgen_box.1", "tetgen_box0.1"):
        node = open(os.path.join(mesh_dir, stem + ".node"), "rb").read()
        ele = open(os.path.join(mesh_dir, stem + ".ele"), "rb").read()
        put("tetgen", f"ok_{stem}.node", node + b"\0" + ele)
    put("tetgen", "ok_one_tet.node",
        b"4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n\0001 4 0\n0 0 1 2 3\n")
    put("tetgen", "bad_index.node",
        b"4 3 1 1\n1 0 0 0 5 1\n2 1 0 0 5 1\n3 0 1 0 5 1\n4 0 0 1 5 1\n\0001 10 1\n"
        b"1 1 2 3 -9223372036854775808 1 1 1 1 1 1 7\n")


def pvd(*steps):
    body = "".join(f'<DataSet timestep="{t}" part="0" file="{f}"/>' for t, f in steps)
    return f'<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">' \
           f"<Collection>{body}</Collection></VTKFile>\n"


def pvd_seeds():
    put("pvd", "ok_one.pvd", pvd((0, "s.vtu")))
    put("pvd", "ok_three.pvd", pvd((0.5, "s.vtu"), (0, "s.vtu"), (1, "s.vtu")))
    put("pvd", "bad_self.pvd", pvd((0, "a.pvd")))
    put("pvd", "bad_cycle.pvd", pvd((0, "b.pvd")))
    put("pvd", "bad_missing.pvd", pvd((0, "nothere.vtu")))


def camera_seeds():
    put("camera_json", "ok_pinhole.json",
        json.dumps({"eye": [3, 2, 1], "target": [0, 0, 0], "up": [0, 0, 1], "vfov_deg": 40}))
    put("camera_json", "ok_ortho.json",
        json.dumps({"eye": [0, -5, 0], "target": [0, 0, 0], "projection": "orthographic",
                    "ortho_height": 2.5}))
    put("camera_json", "ok_defaults.json", json.dumps({"eye": [1, 1, 1], "target": [0, 0, 0]}))
    put("camera_json", "bad_up_parallel.json",
        json.dumps({"eye": [0, 0, 5], "target": [0, 0, 0], "up": [0, 0, 1]}))
    put("camera_json", "bad_huge.json", '{"eye": [1e39, 0, 0], "target": [0, 0, 0]}')


def isot_seeds(isoscope):
    """Small .isot files from `isoscope preprocess` of NRRDs written here, each with the
    selector byte 3 (fix both CRCs) and 0 (keep them) prepended."""
    tmp = os.path.join(HERE, "tmp-isot")
    os.makedirs(tmp, exist_ok=True)
    cases = [("u8", "uchar", "5 4 3", bytes(range(60)), "1"),
             ("f32", "float", "4 4 4", struct.pack("<64f", *[i * 0.25 for i in range(64)]), "2"),
             ("i16", "short", "9 3 2", struct.pack("<54h", *range(-27, 27)), "1")]
    for name, typ, sizes, data, height in cases:
        src = os.path.join(tmp, f"{name}.nrrd")
        with open(src, "wb") as f:
            f.write(nhdr("raw", sizes=sizes, typ=typ).encode() + data)
        out = os.path.join(tmp, f"{name}.isot")
        if os.path.exists(out):
            os.remove(out)
        subprocess.run([isoscope, "preprocess", src, "-o", out, "--treelet-height", height],
                       check=True, capture_output=True)
        img = open(out, "rb").read()
        put("isot", f"ok_{name}_h{height}", b"\x03" + img)
        put("isot", f"ok_{name}_h{height}_crc", b"\x00" + img)
    for f in os.listdir(tmp):
        os.remove(os.path.join(tmp, f))
    os.rmdir(tmp)


def image_seeds(data_dir):
    """MetaImage, VTK image and TIFF seeds: the reader test files (written by SimpleITK, VTK,
    tifffile, Pillow; see tests/data/*/README.md) as ok_ seeds, detached MetaImage headers
    joined to their data as the `metaimage` harness splits them, and a few damaged ones.
    The same inputs start the committed corpora (corpus/<target>/, named by SHA-1 as
    libFuzzer names its inputs) until a campaign's cmin.sh replaces them."""
    import hashlib
    import shutil

    def seed(target, name, data):
        put(target, name, data)
        d = os.path.join(HERE, "..", "corpus", target)
        os.makedirs(d, exist_ok=True)
        with open(os.path.join(d, hashlib.sha1(data).hexdigest()), "wb") as f:
            f.write(data)

    def read(*p):
        return open(os.path.join(data_dir, *p), "rb").read()

    for target in ("metaimage", "vti", "tiff"):
        shutil.rmtree(os.path.join(HERE, "..", "corpus", target), ignore_errors=True)
        shutil.rmtree(os.path.join(HERE, target), ignore_errors=True)
    for f in ("oblique_i16.mha", "float_zlib.mha", "bigendian_i32.mha", "series_4d.mha"):
        seed("metaimage", "ok_" + f, read("metaimage", f))
    for hdr, data in (("sagittal_u8.mhd", "sagittal_u8.raw"), ("flipped_u16.mhd", "flipped_u16.zraw"),
                      ("headersize_end.mhd", "headersize_end.raw"), ("headersize_16.mhd", "headersize_16.raw")):
        seed("metaimage", "ok_" + hdr, read("metaimage", hdr) + read("metaimage", data))
    # A 2-slice pattern and a LIST of plain 2 x 2 x 2 u8 data.
    two = bytes(range(8))
    head = "NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\n"
    seed("metaimage", "ok_pattern.mhd", (head + "ElementDataFile = s%d.raw 0 1 1\n").encode() + two)
    seed("metaimage", "ok_list.mhd", (head + "ElementDataFile = LIST\na.raw\nb.raw\n").encode() + two)
    mha = read("metaimage", "float_zlib.mha")
    seed("metaimage", "bad_zlib_cut.mha", mha[: len(mha) - 100])
    seed("metaimage", "bad_dims_huge.mha", mha.replace(b"DimSize = 10 8 6", b"DimSize = 99999 99999 99999"))
    seed("metaimage", "bad_type.mha", mha.replace(b"MET_FLOAT", b"MET_STRING"))
    # A fuzzing timeout: a printf pattern of 371,225 slices with 371-character names, whose
    # names the harness once listed in full before writing the first few.
    seed("metaimage", "bad_pattern_371225_long_names.mhd",
         b"NDims = 3\nDimSize = 2 2 371225\nElementType = MET_UCHAR\nElementDataFile = s%371+34410d3\n")
    for f in sorted(os.listdir(os.path.join(data_dir, "vtk_image"))):
        if f.endswith(".vti") or f.endswith(".vtk"):
            seed("vti", "ok_" + f, read("vtk_image", f))
    vti = read("vtk_image", "appended_lz4.vti")
    seed("vti", "bad_lz4_cut.vti", vti[: len(vti) - 700])
    seed("vti", "bad_extent.vti", vti.replace(b"2 11 -1 6 0 5", b"2 11 -1 6 0 9"))
    for f in sorted(os.listdir(os.path.join(data_dir, "tiff"))):
        if f.endswith(".tif"):
            seed("tiff", "ok_" + f, read("tiff", f))
    seed("tiff", "ok_slice.tif", read("tiff", "slices", "slice_000.tif"))
    tif = read("tiff", "deflate_i32.tif")
    seed("tiff", "bad_cut.tif", tif[: len(tif) // 2])


def nifti_seeds(nifti_dir):
    """The small files written by nibabel (formats/tests/data/nifti) behind the harness's
    selector byte: 0 a .nii, 1 compressed by the harness, 2 a .nii.gz as is, 3 a pair."""
    def read(name):
        with open(os.path.join(nifti_dir, name), "rb") as f:
            return f.read()
    for name in ["u16.nii", "big_endian.nii", "scaled_i16.nii", "qform_qfac.nii",
                 "sform_oblique.nii"]:
        put("nifti", "ok_" + name, b"\x00" + read(name))
    put("nifti", "ok_compressed_u16.nii", b"\x01" + read("u16.nii"))
    put("nifti", "ok_f64.nii.gz", b"\x02" + read("f64.nii.gz"))
    put("nifti", "ok_pair.hdr", b"\x03" + read("pair.hdr") + read("pair.img"))
    put("nifti", "ok_analyze_spm.hdr", b"\x03" + read("analyze_spm.hdr") + read("analyze_spm.img"))
    # A 4D NIfTI-2 (big-endian) cut to its first step: dim[4] = 1 keeps it valid.
    n2 = bytearray(read("nifti2_be_4d.nii"))
    n2[16 + 8 * 4:24 + 8 * 4] = struct.pack(">q", 1)
    put("nifti", "ok_nifti2_be.nii", b"\x00" + bytes(n2[:544 + 12 * 10 * 8 * 4]))
    # Hostile: a header claiming far more data than follows, a bad gzip stream.
    big = bytearray(read("u16.nii"))
    big[46:48] = struct.pack("<h", 30000)
    put("nifti", "bad_dim3_beyond_data.nii", b"\x00" + bytes(big))
    put("nifti", "bad_not_gzip.nii.gz", b"\x02" + read("u16.nii")[:600])


def dicom_seeds(dicom_dir):
    """Single DICOM files from the reader's fixtures (formats/tests/data/dicom): valid ones of
    every pixel codec, and broken ones. Run make_dicom.py there first."""
    ok = {
        "ok_mr_explicit.dcm": "real/MR_small/MR_small.dcm",
        "ok_mr_implicit.dcm": "real/MR_small_implicit/MR_small_implicit.dcm",
        "ok_mr_bigendian.dcm": "real/MR_small_bigendian/MR_small_bigendian.dcm",
        "ok_mr_rle.dcm": "real/MR_small_RLE/MR_small_RLE.dcm",
        "ok_mr_j2k.dcm": "real/MR_small_jp2klossless/MR_small_jp2klossless.dcm",
        "ok_deflate.dcm": "real/image_dfl/image_dfl.dcm",
        "ok_rtdose_frames.dcm": "real/rtdose/rtdose.dcm",
        "ok_rtdose_rle.dcm": "real/rtdose_rle/rtdose_rle.dcm",
        "ok_enhanced.dcm": "synthetic/multiframe/enhanced.dcm",
        "ok_jpeg_lossless.dcm": "synthetic/jpeg_lossless/jpeg_lossless0.dcm",
        "ok_jpeg_baseline.dcm": "synthetic/jpeg_baseline/baseline.dcm",
        "ok_bits12.dcm": "synthetic/bits12/b0.dcm",
        "bad_truncated.dcm": "bad/truncated/truncated.dcm",
        "bad_short_pixels.dcm": "bad/short_pixels/short_pixels.dcm",
        "bad_jpeg_ls.dcm": "bad/jpeg_ls/jpeg_ls.dcm",
        "bad_report.dcm": "real/test-SR/test-SR.dcm",
        "bad_mr_truncated.dcm": "real/MR_truncated/MR_truncated.dcm",
    }
    for name, src in ok.items():
        with open(os.path.join(dicom_dir, src), "rb") as f:
            put("dicom", name, f.read())
    # seeds/dicom/bad_oom_value_length_not_multiple.dcm is not made here: it is a fuzzing
    # finding kept byte for byte (docs/reliability.md, Fuzzing).


if __name__ == "__main__":
    dicom_seeds(os.path.join(HERE, "..", "..", "tests", "data", "dicom"))
    mesh_dir = os.path.join(HERE, "..", "..", "tests", "data", "mesh")
    nrrd_seeds()
    raw_seeds()
    tetgen_seeds(mesh_dir)
    pvd_seeds()
    camera_seeds()
    image_seeds(os.path.join(HERE, "..", "..", "tests", "data"))
    nifti_seeds(os.path.join(HERE, "..", "..", "tests", "data", "nifti"))
    if len(sys.argv) > 1:
        isot_seeds(sys.argv[1])
