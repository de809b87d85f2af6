//! Hostile-corpus cases of the NIfTI-1/NIfTI-2 and Analyze 7.5 reader: headers written
//! field by field at the offsets of `nifti1.h` (seed: the NIfTI-1 and NIfTI-2 definitions),
//! on the corpus's 5×4×3 volume; each damaged case changes one thing the format forbids.

#[allow(clippy::wildcard_imports)]
use super::*;

// ---- NIfTI ---------------------------------------------------------------------------------

/// A NIfTI-1 (or, without magic, Analyze 7.5) header written field by field at the offsets of
/// `nifti1.h`. The default is the 5×4×3 test volume as int16, unit `pixdim`, `sform_code` 1
/// with the identity affine, a single `.nii` file (magic `n+1`, data at byte 352).
#[derive(Clone)]
struct Nifti1 {
    big: bool,
    sizeof_hdr: i32,
    dim: [i16; 8],
    datatype: i16,
    bitpix: i16,
    pixdim: [f32; 8],
    vox_offset: f32,
    scl: [f32; 2],
    xyzt_units: u8,
    qform_code: i16,
    sform_code: i16,
    /// `quatern_b/c/d`, `qoffset_x/y/z`.
    quatern: [f32; 6],
    srow: [[f32; 4]; 3],
    magic: [u8; 4],
}

impl Nifti1 {
    fn new() -> Self {
        Self {
            big: false,
            sizeof_hdr: 348,
            dim: [3, 5, 4, 3, 1, 1, 1, 1],
            datatype: 4,
            bitpix: 16,
            pixdim: [1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0],
            vox_offset: 352.0,
            scl: [0.0, 0.0],
            xyzt_units: 2,
            qform_code: 0,
            sform_code: 1,
            quatern: [0.0; 6],
            srow: [
                [1.0, 0.0, 0.0, 0.0],
                [0.0, 1.0, 0.0, 0.0],
                [0.0, 0.0, 1.0, 0.0],
            ],
            magic: *b"n+1\0",
        }
    }

    /// The header (348 bytes) and, for a single file, the 4-byte extension flag.
    fn bytes(&self) -> Vec<u8> {
        let mut h = vec![0u8; 348];
        let big = self.big;
        let mut put = |at: usize, b: &[u8]| {
            let mut b = b.to_vec();
            if big {
                b.reverse();
            }
            h[at..at + b.len()].copy_from_slice(&b);
        };
        put(0, &self.sizeof_hdr.to_le_bytes());
        for (i, d) in self.dim.iter().enumerate() {
            put(40 + 2 * i, &d.to_le_bytes());
        }
        put(70, &self.datatype.to_le_bytes());
        put(72, &self.bitpix.to_le_bytes());
        for (i, p) in self.pixdim.iter().enumerate() {
            put(76 + 4 * i, &p.to_le_bytes());
        }
        put(108, &self.vox_offset.to_le_bytes());
        put(112, &self.scl[0].to_le_bytes());
        put(116, &self.scl[1].to_le_bytes());
        put(123, &[self.xyzt_units]);
        put(252, &self.qform_code.to_le_bytes());
        put(254, &self.sform_code.to_le_bytes());
        for (i, q) in self.quatern.iter().enumerate() {
            put(256 + 4 * i, &q.to_le_bytes());
        }
        for (r, row) in self.srow.iter().enumerate() {
            for (c, v) in row.iter().enumerate() {
                put(280 + 16 * r + 4 * c, &v.to_le_bytes());
            }
        }
        h[344..348].copy_from_slice(&self.magic);
        if &self.magic == b"n+1\0" {
            h.extend_from_slice(&[0; 4]);
        }
        h
    }

    /// Header and the test volume's voxels (int16 in the header's byte order).
    fn file(&self) -> Vec<u8> {
        cat(&[&self.bytes(), &i16s(&gradient(), self.big)])
    }
}

/// One change to a valid NIfTI-1 header (a damaged case).
type HeaderEdit = Box<dyn Fn(&mut Nifti1)>;

fn i16s(values: &[f64], big: bool) -> Vec<u8> {
    values
        .iter()
        .flat_map(|&x| {
            let v = x as i16;
            if big {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            }
        })
        .collect()
}

/// A NIfTI-2 header (540 bytes + the extension flag) of the test volume as int16, identity
/// sform, little-endian; `dim` and `vox_offset` as given.
fn nifti2(dim: [i64; 8], vox_offset: i64) -> Vec<u8> {
    let mut h = vec![0u8; 544];
    h[0..4].copy_from_slice(&540i32.to_le_bytes());
    h[4..12].copy_from_slice(b"n+2\0\r\n\x1a\n");
    h[12..14].copy_from_slice(&4i16.to_le_bytes());
    h[14..16].copy_from_slice(&16i16.to_le_bytes());
    for (i, d) in dim.iter().enumerate() {
        h[16 + 8 * i..24 + 8 * i].copy_from_slice(&d.to_le_bytes());
    }
    for i in 0..8 {
        h[104 + 8 * i..112 + 8 * i].copy_from_slice(&1f64.to_le_bytes());
    }
    h[168..176].copy_from_slice(&vox_offset.to_le_bytes());
    h[348..352].copy_from_slice(&1i32.to_le_bytes());
    for r in 0..3 {
        h[400 + 32 * r + 8 * r..408 + 32 * r + 8 * r].copy_from_slice(&1f64.to_le_bytes());
    }
    h[500..504].copy_from_slice(&2i32.to_le_bytes());
    h
}

#[allow(clippy::too_many_lines)] // one list of cases
pub(super) fn nifti_cases(c: &mut Corpus) -> std::io::Result<()> {
    let r = Reader::Nifti;
    let base = Nifti1::new();
    let file = base.file();
    let with = |f: &dyn Fn(&mut Nifti1)| {
        let mut h = base.clone();
        f(&mut h);
        h.file()
    };
    let pair = |h: &Nifti1, img: Vec<u8>| {
        vec![
            ("v.hdr".to_string(), Entry::File(h.bytes())),
            ("v.img".to_string(), Entry::File(img)),
        ]
    };
    let mut pair_header = base.clone();
    pair_header.magic = *b"ni1\0";
    pair_header.vox_offset = 0.0;
    let data = i16s(&gradient(), false);

    // Valid: both byte orders, gzip, pairs (opened by either part), qform, scaling, 4D,
    // NIfTI-2, Analyze 7.5, bytes after the data, float32.
    c.valid(r, "nifti_valid", "v.nii", file.clone())?;
    c.valid(r, "nifti_valid_big", "v.nii", with(&|h| h.big = true))?;
    c.valid(r, "nifti_valid_gz", "v.nii.gz", gzip(&file))?;
    c.add(
        r,
        Kind::Valid,
        "nifti_valid_pair",
        pair(&pair_header, data.clone()),
        "v.hdr",
    )?
    .expect = Expect::Renders;
    c.add(
        r,
        Kind::Valid,
        "nifti_valid_pair_img",
        pair(&pair_header, data.clone()),
        "v.img",
    )?
    .expect = Expect::Renders;
    let mut analyze = pair_header.clone();
    analyze.magic = [0; 4];
    c.add(
        r,
        Kind::Valid,
        "nifti_valid_analyze",
        pair(&analyze, data.clone()),
        "v.hdr",
    )?
    .expect = Expect::Renders;
    c.valid(
        r,
        "nifti_valid_qform_oblique",
        "v.nii",
        with(&|h| {
            h.sform_code = 0;
            h.qform_code = 1;
            h.pixdim[0] = -1.0;
            h.quatern = [0.3, -0.2, 0.5, 10.0, -4.0, 2.5];
        }),
    )?;
    c.valid(
        r,
        "nifti_valid_scaled",
        "v.nii",
        with(&|h| h.scl = [0.5, -3.0]),
    )?;
    let four_d = {
        let mut h = base.clone();
        h.dim[0] = 4;
        h.dim[4] = 2;
        h.pixdim[4] = 1.5;
        let back: Vec<f64> = gradient().iter().map(|x| 16.0 - x).collect();
        cat(&[&h.bytes(), &data, &i16s(&back, false)])
    };
    c.valid(r, "nifti_valid_4d", "v.nii", four_d.clone())?;
    c.valid(r, "nifti_valid_dim5_ones", "v.nii", with(&|h| h.dim[0] = 5))?;
    c.valid(
        r,
        "nifti_valid_nifti2",
        "v.nii",
        cat(&[&nifti2([3, 5, 4, 3, 1, 1, 1, 1], 544), &data]),
    )?;
    c.valid(
        r,
        "nifti_valid_trailing",
        "v.nii",
        cat(&[&file, b"trailing bytes"]),
    )?;
    let mut f32h = base.clone();
    f32h.datatype = 16;
    f32h.bitpix = 32;
    c.valid(
        r,
        "nifti_valid_f32",
        "v.nii",
        cat(&[&f32h.bytes(), &f32s_le(&gradient())]),
    )?;
    // A gzip bomb: 120 bytes declared, 16 MiB of zeros after them; only the declared bytes
    // are kept (the rest is read through to check the stream, never stored).
    c.valid(
        r,
        "nifti_valid_gzip_surplus",
        "v.nii.gz",
        gzip(&cat(&[&file, &vec![0u8; 16 << 20]])),
    )?;

    // Truncated: anywhere in the header or the data; a gzip stream of incompressible data
    // cut before its last data byte; a pair's image cut short.
    c.truncations(r, "nifti", "v.nii", &file, &[0..file.len()], 12)?;
    let noise: Vec<u8> = (0..2 * 60u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    let noisy = gzip(&cat(&[&base.bytes(), &noise]));
    c.truncations(
        r,
        "nifti_gz",
        "v.nii.gz",
        &noisy,
        &[10..noisy.len() - 12],
        6,
    )?;
    for cut in [1, data.len() / 2, data.len() - 1] {
        c.add(
            r,
            Kind::Truncated,
            &format!("nifti_pair_img_cut{cut}"),
            pair(&pair_header, data[..cut].to_vec()),
            "v.hdr",
        )?;
    }

    // Lying headers.
    let lying: Vec<(&str, HeaderEdit)> = vec![
        ("sizeof_hdr_347", Box::new(|h| h.sizeof_hdr = 347)),
        ("sizeof_hdr_0", Box::new(|h| h.sizeof_hdr = 0)),
        ("dim0_zero", Box::new(|h| h.dim[0] = 0)),
        ("dim0_eight", Box::new(|h| h.dim[0] = 8)),
        ("dim2_zero", Box::new(|h| h.dim[2] = 0)),
        ("dim2_negative", Box::new(|h| h.dim[2] = -5)),
        ("dim3_beyond_data", Box::new(|h| h.dim[3] = 400)),
        (
            "dim4_steps_missing",
            Box::new(|h| {
                h.dim[0] = 4;
                h.dim[4] = 3;
            }),
        ),
        (
            "dim5_vector",
            Box::new(|h| {
                h.dim[0] = 5;
                h.dim[5] = 3;
            }),
        ),
        ("vox_offset_in_header", Box::new(|h| h.vox_offset = 100.0)),
        ("vox_offset_fraction", Box::new(|h| h.vox_offset = 352.5)),
        ("vox_offset_nan", Box::new(|h| h.vox_offset = f32::NAN)),
        (
            "datatype_int64",
            Box::new(|h| {
                h.datatype = 1024;
                h.bitpix = 64;
            }),
        ),
        ("datatype_uint64", Box::new(|h| h.datatype = 1280)),
        ("datatype_complex", Box::new(|h| h.datatype = 32)),
        ("datatype_rgb", Box::new(|h| h.datatype = 128)),
        ("datatype_rgba", Box::new(|h| h.datatype = 2304)),
        ("datatype_unknown", Box::new(|h| h.datatype = 0)),
        ("datatype_not_a_code", Box::new(|h| h.datatype = 3)),
        (
            "scl_inter_infinite",
            Box::new(|h| h.scl = [1.0, f32::INFINITY]),
        ),
        ("pair_magic_in_nii", Box::new(|h| h.magic = *b"ni1\0")),
        (
            "float64_type_int16_data",
            Box::new(|h| {
                h.datatype = 64;
                h.bitpix = 64;
            }),
        ),
    ];
    for (name, f) in &lying {
        c.one(
            r,
            Kind::LyingHeader,
            &format!("nifti_{name}"),
            "v.nii",
            with(f.as_ref()),
        )?;
    }
    let mut n2 = nifti2([3, 5, 4, 3, 1, 1, 1, 1], 544);
    n2[4..8].copy_from_slice(b"nx2\0");
    c.one(
        r,
        Kind::LyingHeader,
        "nifti2_bad_magic",
        "v.nii",
        cat(&[&n2, &data]),
    )?;

    // Overflowing sizes (NIfTI-2's 64-bit dims) and offsets far beyond the file.
    for (name, dim) in [
        (
            "nifti2_dims_2e40",
            [3, 1 << 40, 1 << 40, 1 << 40, 1, 1, 1, 1],
        ),
        ("nifti2_dims_max", [3, i64::MAX, i64::MAX, 2, 1, 1, 1, 1]),
        ("nifti2_steps_2e62", [4, 5, 4, 3, 1 << 62, 1, 1, 1]),
    ] {
        c.one(
            r,
            Kind::Overflow,
            name,
            "v.nii",
            cat(&[&nifti2(dim, 544), &data]),
        )?;
    }
    c.one(
        r,
        Kind::HugeSkip,
        "nifti_vox_offset_2e40",
        "v.nii",
        with(&|h| h.vox_offset = 2f32.powi(40)),
    )?;
    c.one(
        r,
        Kind::HugeSkip,
        "nifti_vox_offset_f32_max",
        "v.nii",
        with(&|h| h.vox_offset = f32::MAX),
    )?;
    c.one(
        r,
        Kind::HugeSkip,
        "nifti_vox_offset_gz_2e30",
        "v.nii.gz",
        gzip(&with(&|h| h.vox_offset = 1e30)),
    )?;
    c.one(
        r,
        Kind::HugeSkip,
        "nifti_vox_offset_gz_beyond",
        "v.nii.gz",
        gzip(&with(&|h| h.vox_offset = 4096.0)),
    )?;
    c.one(
        r,
        Kind::HugeSkip,
        "nifti2_vox_offset_max",
        "v.nii",
        cat(&[&nifti2([3, 5, 4, 3, 1, 1, 1, 1], i64::MAX), &data]),
    )?;

    // Streams that are not what `.gz` says.
    let gz = gzip(&file);
    c.one(
        r,
        Kind::BadStream,
        "nifti_gz_not_gzip",
        "v.nii.gz",
        file.clone(),
    )?;
    c.one(
        r,
        Kind::BadStream,
        "nifti_gz_header_only",
        "v.nii.gz",
        gzip(&base.bytes()),
    )?;
    let mut crc = gz.clone();
    let n = crc.len();
    crc[n - 6] ^= 0x5a;
    c.one(r, Kind::BadStream, "nifti_gz_bad_crc", "v.nii.gz", crc)?;
    let mut len = gz.clone();
    len[n - 3] ^= 0x01;
    c.one(r, Kind::BadStream, "nifti_gz_bad_length", "v.nii.gz", len)?;
    c.add(
        r,
        Kind::BadStream,
        "nifti_img_gz_not_gzip",
        vec![
            ("v.hdr".to_string(), Entry::File(pair_header.bytes())),
            ("v.img.gz".to_string(), Entry::File(data.clone())),
        ],
        "v.hdr",
    )?;

    // Geometry no grid can have.
    let geometry: Vec<(&str, HeaderEdit)> = vec![
        ("sform_zero", Box::new(|h| h.srow = [[0.0; 4]; 3])),
        ("sform_nan", Box::new(|h| h.srow[1][2] = f32::NAN)),
        (
            "sform_singular",
            Box::new(|h| {
                h.srow = [
                    [1.0, 1.0, 0.0, 0.0],
                    [1.0, 1.0, 0.0, 0.0],
                    [0.0, 0.0, 1.0, 0.0],
                ];
            }),
        ),
        ("sform_far", Box::new(|h| h.srow[0][3] = 1e30)),
        ("sform_huge_spacing", Box::new(|h| h.srow[2][2] = 1e35)),
        (
            "qform_not_rotation",
            Box::new(|h| {
                h.sform_code = 0;
                h.qform_code = 1;
                h.quatern[0] = 2.0;
            }),
        ),
        (
            "qform_offset_inf",
            Box::new(|h| {
                h.sform_code = 0;
                h.qform_code = 1;
                h.quatern[4] = f32::INFINITY;
            }),
        ),
        (
            "pixdim_nan",
            Box::new(|h| {
                h.sform_code = 0;
                h.pixdim[2] = f32::NAN;
            }),
        ),
        (
            "pixdim_huge",
            Box::new(|h| {
                h.sform_code = 0;
                h.pixdim[1] = 1e38;
            }),
        ),
    ];
    for (name, f) in &geometry {
        c.one(
            r,
            Kind::BadGeometry,
            &format!("nifti_{name}"),
            "v.nii",
            with(f.as_ref()),
        )?;
    }

    // A header without its image, and the special files.
    c.add(
        r,
        Kind::SpecialFile,
        "nifti_pair_img_missing",
        vec![("v.hdr".to_string(), Entry::File(pair_header.bytes()))],
        "v.hdr",
    )?;
    c.add(
        r,
        Kind::SpecialFile,
        "nifti_pair_img_fifo",
        vec![
            ("v.hdr".to_string(), Entry::File(pair_header.bytes())),
            ("v.img".to_string(), Entry::Fifo),
        ],
        "v.hdr",
    )?;
    c.add(
        r,
        Kind::SpecialFile,
        "nifti_pair_img_devzero",
        vec![
            ("v.hdr".to_string(), Entry::File(pair_header.bytes())),
            ("v.img".to_string(), Entry::Link("/dev/zero".into())),
        ],
        "v.hdr",
    )?;
    c.special(r, "nifti_special", "x.nii")?;
    Ok(())
}
