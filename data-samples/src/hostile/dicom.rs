//! Hostile-corpus cases of the DICOM reader: files written element by element (PS3.5 data
//! encodings, PS3.10 file meta, PS3.3 image modules), folders, DICOMDIRs and multi-frame
//! objects; each damaged case changes one thing the standard forbids.

#[allow(clippy::wildcard_imports)]
use super::*;

/// Explicit VRs with a 16-bit length (PS3.5 Table 7.1-2).
const DCM_SHORT_VRS: [&str; 21] = [
    "AE", "AS", "AT", "CS", "DA", "DS", "DT", "FL", "FD", "IS", "LO", "LT", "PN", "SH", "SL", "SS",
    "ST", "TM", "UI", "UL", "US",
];

/// A DICOM element in explicit VR little endian (PS3.5 §7.1.2): 16-bit lengths for the VRs
/// of Table 7.1-2, reserved bytes and 32-bit lengths for the others. Odd values are padded
/// (UI and binary with NUL, text with a space), as §6.2 requires.
fn dcm_el(group: u16, element: u16, vr: &str, value: &[u8]) -> Vec<u8> {
    let mut v = value.to_vec();
    if v.len() % 2 == 1 {
        v.push(if matches!(vr, "UI" | "OB" | "OW" | "UN") {
            0
        } else {
            b' '
        });
    }
    let mut b = Vec::with_capacity(v.len() + 12);
    b.extend(group.to_le_bytes());
    b.extend(element.to_le_bytes());
    b.extend(vr.as_bytes());
    if DCM_SHORT_VRS.contains(&vr) {
        b.extend((v.len() as u16).to_le_bytes());
    } else {
        b.extend([0, 0]);
        b.extend((v.len() as u32).to_le_bytes());
    }
    b.extend(v);
    b
}

/// An element of undefined length (a sequence or encapsulated pixel data), its items, and the
/// sequence delimiter.
fn dcm_undefined(group: u16, element: u16, vr: &str, items: &[Vec<u8>]) -> Vec<u8> {
    let mut b = Vec::new();
    b.extend(group.to_le_bytes());
    b.extend(element.to_le_bytes());
    b.extend(vr.as_bytes());
    b.extend([0, 0]);
    b.extend(u32::MAX.to_le_bytes());
    for item in items {
        b.extend(dcm_item(item));
    }
    b.extend([0xFE, 0xFF, 0xDD, 0xE0, 0, 0, 0, 0]);
    b
}

/// An item of defined length (FFFE,E000).
fn dcm_item(value: &[u8]) -> Vec<u8> {
    let mut b = vec![0xFE, 0xFF, 0x00, 0xE0];
    b.extend((value.len() as u32).to_le_bytes());
    b.extend(value);
    b
}

fn us(v: u16) -> Vec<u8> {
    v.to_le_bytes().to_vec()
}

/// A DICOM Part 10 file (PS3.10 §7.1): preamble, `DICM`, the file meta group, then the data
/// set `elements` (already encoded, in ascending tag order).
fn dcm_file(sop_class: &str, ts: &str, elements: &[Vec<u8>]) -> Vec<u8> {
    let mut meta = Vec::new();
    meta.extend(dcm_el(0x0002, 0x0001, "OB", &[0, 1]));
    meta.extend(dcm_el(0x0002, 0x0002, "UI", sop_class.as_bytes()));
    meta.extend(dcm_el(0x0002, 0x0003, "UI", b"1.2.826.0.1.3680043.8.498.7"));
    meta.extend(dcm_el(0x0002, 0x0010, "UI", ts.as_bytes()));
    let mut b = vec![0u8; 128];
    b.extend(b"DICM");
    b.extend(dcm_el(
        0x0002,
        0x0000,
        "UL",
        &(meta.len() as u32).to_le_bytes(),
    ));
    b.extend(meta);
    for e in elements {
        b.extend(e);
    }
    b
}

const CT_IMAGE: &str = "1.2.840.10008.5.1.4.1.1.2";
const EXPLICIT_LE: &str = "1.2.840.10008.1.2.1";

/// The attributes of an 8×6 u16 CT slice at z, in tag order, before the pixel data; `edit`
/// replaces an attribute (by tag) or adds nothing when it returns `None`.
fn dcm_slice_attributes(z: f64, series: &str, extra: &[Vec<u8>]) -> Vec<Vec<u8>> {
    let mut e = vec![
        dcm_el(0x0008, 0x0016, "UI", CT_IMAGE.as_bytes()),
        dcm_el(
            0x0008,
            0x0018,
            "UI",
            format!("1.2.826.0.1.3680043.8.498.8.{}", (z * 10.0) as i64).as_bytes(),
        ),
        dcm_el(0x0008, 0x0060, "CS", b"CT"),
        dcm_el(0x0020, 0x000E, "UI", series.as_bytes()),
        dcm_el(0x0020, 0x0032, "DS", format!("0\\0\\{z}").as_bytes()),
        dcm_el(0x0020, 0x0037, "DS", b"1\\0\\0\\0\\1\\0"),
        dcm_el(0x0028, 0x0002, "US", &us(1)),
        dcm_el(0x0028, 0x0004, "CS", b"MONOCHROME2"),
        dcm_el(0x0028, 0x0010, "US", &us(6)),
        dcm_el(0x0028, 0x0011, "US", &us(8)),
        dcm_el(0x0028, 0x0030, "DS", b"0.5\\0.5"),
        dcm_el(0x0028, 0x0100, "US", &us(16)),
        dcm_el(0x0028, 0x0101, "US", &us(16)),
        dcm_el(0x0028, 0x0102, "US", &us(15)),
        dcm_el(0x0028, 0x0103, "US", &us(0)),
    ];
    // Replace same-tag elements, insert the others in tag order.
    for x in extra {
        let tag = |b: &[u8]| {
            (
                u16::from_le_bytes([b[0], b[1]]),
                u16::from_le_bytes([b[2], b[3]]),
            )
        };
        let t = tag(x);
        if let Some(i) = e.iter().position(|y| tag(y) == t) {
            e[i].clone_from(x);
        } else {
            let at = e.iter().position(|y| tag(y) > t).unwrap_or(e.len());
            e.insert(at, x.clone());
        }
    }
    e
}

/// 8×6 u16 samples of a ball around the volume's centre (slice `k` of 3).
fn dcm_pixels(k: usize) -> Vec<u16> {
    let mut v = Vec::with_capacity(48);
    for j in 0..6 {
        for i in 0..8 {
            let (x, y, z) = (i as f64 - 3.5, j as f64 - 2.5, k as f64 - 1.0);
            v.push((1000.0 - 60.0 * (x * x + y * y + 4.0 * z * z)).max(0.0) as u16);
        }
    }
    v
}

fn dcm_native(pixels: &[u16]) -> Vec<u8> {
    dcm_el(
        0x7FE0,
        0x0010,
        "OW",
        &pixels
            .iter()
            .flat_map(|p| p.to_le_bytes())
            .collect::<Vec<_>>(),
    )
}

/// A valid slice file at slice `k` (z = 2k) of series `series`, with `extra` attributes.
fn dcm_slice(k: usize, series: &str, extra: &[Vec<u8>]) -> Vec<u8> {
    let mut e = dcm_slice_attributes(2.0 * k as f64, series, extra);
    e.push(dcm_native(&dcm_pixels(k)));
    dcm_file(CT_IMAGE, EXPLICIT_LE, &e)
}

/// PackBits with literal runs only (PS3.5 Annex G.3.1).
fn packbits(bytes: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    for chunk in bytes.chunks(128) {
        out.push((chunk.len() - 1) as u8);
        out.extend(chunk);
    }
    out
}

/// An RLE Lossless frame of u16 samples: header (2 segments), MSB segment, LSB segment.
fn rle_frame(pixels: &[u16]) -> Vec<u8> {
    let msb: Vec<u8> = pixels.iter().map(|p| (p >> 8) as u8).collect();
    let lsb: Vec<u8> = pixels.iter().map(|p| (p & 0xFF) as u8).collect();
    let (s0, s1) = (packbits(&msb), packbits(&lsb));
    let mut header = vec![0u8; 64];
    header[..4].copy_from_slice(&2u32.to_le_bytes());
    header[4..8].copy_from_slice(&64u32.to_le_bytes());
    header[8..12].copy_from_slice(&(64 + s0.len() as u32).to_le_bytes());
    cat(&[&header, &s0, &s1])
}

pub(super) fn dcm_cases(c: &mut Corpus) -> std::io::Result<()> {
    let r = Reader::Dicom;
    let series = "1.2.826.0.1.3680043.8.498.9";
    let three = |extra: &[Vec<u8>]| -> Files {
        (0..3)
            .map(|k| {
                (
                    format!("s{k}.dcm"),
                    Entry::File(dcm_slice(k, series, extra)),
                )
            })
            .collect()
    };
    // Valid: a folder, one file of it (its series), a DICOMDIR, RLE, multi-frame.
    c.add(r, Kind::Valid, "dicom_folder", three(&[]), ".")?
        .expect = Expect::Renders;
    c.add(r, Kind::Valid, "dicom_one_file", three(&[]), "s1.dcm")?
        .expect = Expect::Renders;
    let record = |name: &str| {
        cat(&[
            &dcm_el(0x0004, 0x1430, "CS", b"IMAGE"),
            &dcm_el(0x0004, 0x1500, "CS", format!("IMG\\{name}").as_bytes()),
        ])
    };
    let dicomdir = |names: &[&str]| {
        let items: Vec<Vec<u8>> = names.iter().map(|n| record(n)).collect();
        dcm_file(
            "1.2.840.10008.1.3.10",
            EXPLICIT_LE,
            &[dcm_undefined(0x0004, 0x1220, "SQ", &items)],
        )
    };
    let mut with_dir: Files = (0..3)
        .map(|k| (format!("IMG/S{k}"), Entry::File(dcm_slice(k, series, &[]))))
        .collect();
    with_dir.push((
        "DICOMDIR".into(),
        Entry::File(dicomdir(&["S0", "S1", "S2"])),
    ));
    c.add(r, Kind::Valid, "dicom_dicomdir", with_dir, "DICOMDIR")?
        .expect = Expect::Renders;
    let rle: Files = (0..3)
        .map(|k| {
            let mut e = dcm_slice_attributes(2.0 * k as f64, series, &[]);
            e.push(dcm_undefined(
                0x7FE0,
                0x0010,
                "OB",
                &[Vec::new(), rle_frame(&dcm_pixels(k))],
            ));
            (
                format!("r{k}.dcm"),
                Entry::File(dcm_file(CT_IMAGE, "1.2.840.10008.1.2.5", &e)),
            )
        })
        .collect();
    c.add(r, Kind::Valid, "dicom_rle", rle, ".")?.expect = Expect::Renders;
    // Enhanced multi-frame: 3 frames, per-frame positions, shared orientation and spacing.
    let per_frame: Vec<Vec<u8>> = (0..3)
        .map(|k| {
            dcm_undefined(
                0x0020,
                0x9113,
                "SQ",
                &[dcm_el(
                    0x0020,
                    0x0032,
                    "DS",
                    format!("0\\0\\{}", 3.0 * k as f64).as_bytes(),
                )],
            )
        })
        .collect();
    let shared = cat(&[
        &dcm_undefined(
            0x0020,
            0x9116,
            "SQ",
            &[dcm_el(0x0020, 0x0037, "DS", b"1\\0\\0\\0\\1\\0")],
        ),
        &dcm_undefined(
            0x0028,
            0x9110,
            "SQ",
            &[dcm_el(0x0028, 0x0030, "DS", b"0.5\\0.5")],
        ),
    ]);
    let mut mf = dcm_slice_attributes(0.0, series, &[dcm_el(0x0028, 0x0008, "IS", b"3")]);
    mf.retain(|e| {
        !(e[0..4] == [0x20, 0x00, 0x32, 0x00]
            || e[0..4] == [0x20, 0x00, 0x37, 0x00]
            || e[0..4] == [0x28, 0x00, 0x30, 0x00])
    });
    mf.push(dcm_undefined(0x5200, 0x9229, "SQ", &[shared]));
    mf.push(dcm_undefined(0x5200, 0x9230, "SQ", &per_frame));
    let all: Vec<u16> = (0..3).flat_map(dcm_pixels).collect();
    mf.push(dcm_native(&all));
    let mf_file = dcm_file("1.2.840.10008.5.1.4.1.1.2.1", EXPLICIT_LE, &mf);
    c.valid(r, "dicom_multiframe", "mf.dcm", mf_file)?;

    // Truncated anywhere: inside the preamble, the meta group, an attribute or the pixels.
    let base = dcm_slice(0, series, &[]);
    c.truncations(r, "dicom", "s.dcm", &base, &[0..base.len()], 12)?;
    c.truncations(
        r,
        "dicom_mf",
        "mf.dcm",
        &mf_file_bytes(&mf),
        &[0..mf_file_bytes(&mf).len()],
        6,
    )?;

    // Lying headers.
    let one = |c: &mut Corpus, kind: Kind, name: &str, bytes: Vec<u8>| {
        c.one(r, kind, name, "s.dcm", bytes).map(|_| ())
    };
    one(
        c,
        Kind::LyingHeader,
        "dicom_rows_beyond_pixels",
        dcm_slice(0, series, &[dcm_el(0x0028, 0x0010, "US", &us(600))]),
    )?;
    one(
        c,
        Kind::LyingHeader,
        "dicom_bits_beyond_pixels",
        dcm_slice(
            0,
            series,
            &[
                dcm_el(0x0028, 0x0100, "US", &us(32)),
                dcm_el(0x0028, 0x0101, "US", &us(32)),
                dcm_el(0x0028, 0x0102, "US", &us(31)),
            ],
        ),
    )?;
    one(
        c,
        Kind::LyingHeader,
        "dicom_frames_beyond_pixels",
        dcm_slice(0, series, &[dcm_el(0x0028, 0x0008, "IS", b"1000")]),
    )?;
    one(
        c,
        Kind::LyingHeader,
        "dicom_high_bit_beyond",
        dcm_slice(0, series, &[dcm_el(0x0028, 0x0102, "US", &us(40))]),
    )?;
    one(
        c,
        Kind::LyingHeader,
        "dicom_bits_stored_zero",
        dcm_slice(0, series, &[dcm_el(0x0028, 0x0101, "US", &us(0))]),
    )?;
    one(
        c,
        Kind::LyingHeader,
        "dicom_rows_zero",
        dcm_slice(0, series, &[dcm_el(0x0028, 0x0010, "US", &us(0))]),
    )?;
    one(c, Kind::LyingHeader, "dicom_no_rows", {
        let mut e = dcm_slice_attributes(0.0, series, &[]);
        e.retain(|x| x[0..4] != [0x28, 0x00, 0x10, 0x00]);
        e.push(dcm_native(&dcm_pixels(0)));
        dcm_file(CT_IMAGE, EXPLICIT_LE, &e)
    })?;
    let mut huge_len = base.clone();
    let at = find(&huge_len, "MONOCHROME2").start - 4; // the length of PhotometricInterpretation
    huge_len[at..at + 2].copy_from_slice(&0xFFF0u16.to_le_bytes());
    one(c, Kind::LyingHeader, "dicom_length_beyond_file", huge_len)?;
    let mut ob_huge = dcm_slice_attributes(0.0, series, &[]);
    ob_huge.push(cat(&[
        &[0x09, 0x00, 0x10, 0x00],
        b"OB",
        &[0, 0],
        &0xFFFF_FFF0u32.to_le_bytes(),
        &[0u8; 64],
    ]));
    one(
        c,
        Kind::LyingHeader,
        "dicom_ob_4gb",
        dcm_file(CT_IMAGE, EXPLICIT_LE, &ob_huge),
    )?;
    let mut e = dcm_slice_attributes(0.0, series, &[]);
    e.push(dcm_native(&dcm_pixels(0)));
    one(
        c,
        Kind::LyingHeader,
        "dicom_jpeg_ls_syntax",
        dcm_file(CT_IMAGE, "1.2.840.10008.1.2.4.80", &e),
    )?;
    one(
        c,
        Kind::LyingHeader,
        "dicom_private_syntax",
        dcm_file(CT_IMAGE, "1.2.3.4.5", &e),
    )?;
    one(c, Kind::LyingHeader, "dicom_no_syntax", {
        let mut b = vec![0u8; 128];
        b.extend(b"DICM");
        b.extend(dcm_el(0x0002, 0x0002, "UI", CT_IMAGE.as_bytes()));
        for x in &e {
            b.extend(x);
        }
        b
    })?;
    one(
        c,
        Kind::LyingHeader,
        "dicom_color",
        dcm_slice(
            0,
            series,
            &[
                dcm_el(0x0028, 0x0002, "US", &us(3)),
                dcm_el(0x0028, 0x0004, "CS", b"RGB"),
            ],
        ),
    )?;
    one(c, Kind::LyingHeader, "dicom_no_pixel_data", {
        dcm_file(
            CT_IMAGE,
            EXPLICIT_LE,
            &dcm_slice_attributes(0.0, series, &[]),
        )
    })?;
    one(c, Kind::LyingHeader, "dicom_rle_frames_beyond_fragments", {
        let mut e = dcm_slice_attributes(0.0, series, &[dcm_el(0x0028, 0x0008, "IS", b"5")]);
        e.push(dcm_undefined(
            0x7FE0,
            0x0010,
            "OB",
            &[Vec::new(), rle_frame(&dcm_pixels(0))],
        ));
        dcm_file(CT_IMAGE, "1.2.840.10008.1.2.5", &e)
    })?;
    // Overflow: the largest image a header can describe.
    one(
        c,
        Kind::Overflow,
        "dicom_dims_overflow",
        dcm_slice(
            0,
            series,
            &[
                dcm_el(0x0028, 0x0008, "IS", b"2147483647"),
                dcm_el(0x0028, 0x0010, "US", &us(65535)),
                dcm_el(0x0028, 0x0011, "US", &us(65535)),
            ],
        ),
    )?;
    one(c, Kind::Overflow, "dicom_rle_dims_overflow", {
        let mut e = dcm_slice_attributes(
            0.0,
            series,
            &[
                dcm_el(0x0028, 0x0010, "US", &us(65535)),
                dcm_el(0x0028, 0x0011, "US", &us(65535)),
            ],
        );
        e.push(dcm_undefined(
            0x7FE0,
            0x0010,
            "OB",
            &[Vec::new(), rle_frame(&dcm_pixels(0))],
        ));
        dcm_file(CT_IMAGE, "1.2.840.10008.1.2.5", &e)
    })?;
    // Bad streams.
    let encapsulated = |ts: &str, fragment: Vec<u8>| {
        let mut e = dcm_slice_attributes(0.0, series, &[]);
        e.push(dcm_undefined(0x7FE0, 0x0010, "OB", &[Vec::new(), fragment]));
        dcm_file(CT_IMAGE, ts, &e)
    };
    let good_rle = rle_frame(&dcm_pixels(0));
    let mut bad_offsets = good_rle.clone();
    bad_offsets[8..12].copy_from_slice(&9999u32.to_le_bytes());
    one(
        c,
        Kind::BadStream,
        "dicom_rle_bad_offsets",
        encapsulated("1.2.840.10008.1.2.5", bad_offsets),
    )?;
    one(
        c,
        Kind::BadStream,
        "dicom_rle_short_segment",
        encapsulated(
            "1.2.840.10008.1.2.5",
            good_rle[..good_rle.len() - 20].to_vec(),
        ),
    )?;
    let mut three_segments = good_rle.clone();
    three_segments[..4].copy_from_slice(&3u32.to_le_bytes());
    one(
        c,
        Kind::BadStream,
        "dicom_rle_segment_count",
        encapsulated("1.2.840.10008.1.2.5", three_segments),
    )?;
    one(
        c,
        Kind::BadStream,
        "dicom_rle_tiny",
        encapsulated("1.2.840.10008.1.2.5", vec![1, 0, 0, 0]),
    )?;
    let junk: Vec<u8> = (0..96u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 11) as u8)
        .collect();
    one(
        c,
        Kind::BadStream,
        "dicom_jpeg_junk",
        encapsulated("1.2.840.10008.1.2.4.70", cat(&[&[0xFF, 0xD8], &junk])),
    )?;
    one(
        c,
        Kind::BadStream,
        "dicom_jpeg_baseline_junk",
        encapsulated(
            "1.2.840.10008.1.2.4.50",
            cat(&[
                &[0xFF, 0xD8, 0xFF, 0xC0, 0, 11, 8, 0, 6, 0, 8, 1, 1, 0x11, 0],
                &junk,
            ]),
        ),
    )?;
    one(
        c,
        Kind::BadStream,
        "dicom_j2k_junk",
        encapsulated(
            "1.2.840.10008.1.2.4.90",
            cat(&[&[0xFF, 0x4F, 0xFF, 0x51], &junk]),
        ),
    )?;
    one(
        c,
        Kind::BadStream,
        "dicom_deflated_frame_junk",
        encapsulated("1.2.840.10008.1.2.8.1", junk.clone()),
    )?;
    one(c, Kind::BadStream, "dicom_deflated_dataset_junk", {
        let mut b = dcm_file(CT_IMAGE, "1.2.840.10008.1.2.1.99", &[]);
        b.extend(&junk);
        b
    })?;
    one(c, Kind::BadStream, "dicom_fragment_undefined_item", {
        let mut e = dcm_slice_attributes(0.0, series, &[]);
        e.push(cat(&[
            &[0xE0, 0x7F, 0x10, 0x00],
            b"OB",
            &[0, 0],
            &u32::MAX.to_le_bytes(),
            &[0xFE, 0xFF, 0x00, 0xE0],
            &u32::MAX.to_le_bytes(),
            &[0u8; 16],
        ]));
        dcm_file(CT_IMAGE, "1.2.840.10008.1.2.5", &e)
    })?;
    one(c, Kind::BadStream, "dicom_no_sequence_delimiter", {
        let mut b = encapsulated("1.2.840.10008.1.2.5", rle_frame(&dcm_pixels(0)));
        b.truncate(b.len() - 8);
        b
    })?;
    // Bad geometry (folders of three slices, and single files).
    let folder = |c: &mut Corpus, kind: Kind, name: &str, files: Files| {
        c.add(r, kind, name, files, ".").map(|_| ())
    };
    let z = |k: usize, zz: f64| {
        (
            format!("s{k}.dcm"),
            Entry::File({
                let mut e = dcm_slice_attributes(zz, series, &[]);
                e.push(dcm_native(&dcm_pixels(k)));
                dcm_file(CT_IMAGE, EXPLICIT_LE, &e)
            }),
        )
    };
    folder(
        c,
        Kind::BadGeometry,
        "dicom_duplicate_positions",
        vec![z(0, 0.0), z(1, 2.0), z(2, 2.0)],
    )?;
    folder(
        c,
        Kind::BadGeometry,
        "dicom_missing_slices",
        vec![
            z(0, 0.0),
            z(1, 2.0),
            z(2, 4.0),
            ("s3.dcm".into(), z(2, 10.0).1),
        ],
    )?;
    folder(
        c,
        Kind::BadGeometry,
        "dicom_positions_off_line",
        vec![
            z(0, 0.0),
            z(1, 2.0),
            (
                "s2.dcm".into(),
                Entry::File(dcm_slice(
                    2,
                    series,
                    &[dcm_el(0x0020, 0x0032, "DS", b"7\\-3\\4")],
                )),
            ),
        ],
    )?;
    folder(
        c,
        Kind::BadGeometry,
        "dicom_no_positions",
        (0..3)
            .map(|k| {
                (
                    format!("s{k}.dcm"),
                    Entry::File({
                        let mut e = dcm_slice_attributes(0.0, series, &[]);
                        e.retain(|x| x[0..4] != [0x20, 0x00, 0x32, 0x00]);
                        e.push(dcm_native(&dcm_pixels(k)));
                        dcm_file(CT_IMAGE, EXPLICIT_LE, &e)
                    }),
                )
            })
            .collect(),
    )?;
    for (name, el) in [
        (
            "dicom_spacing_zero",
            dcm_el(0x0028, 0x0030, "DS", b"0\\0.5"),
        ),
        (
            "dicom_spacing_nan",
            dcm_el(0x0028, 0x0030, "DS", b"nan\\0.5"),
        ),
        (
            "dicom_orientation_zero",
            dcm_el(0x0020, 0x0037, "DS", b"0\\0\\0\\0\\0\\0"),
        ),
        (
            "dicom_orientation_parallel",
            dcm_el(0x0020, 0x0037, "DS", b"1\\0\\0\\1\\0\\0"),
        ),
        (
            "dicom_position_inf",
            dcm_el(0x0020, 0x0032, "DS", b"0\\inf\\0"),
        ),
        (
            "dicom_position_two_values",
            dcm_el(0x0020, 0x0032, "DS", b"0\\0"),
        ),
        (
            "dicom_position_far",
            dcm_el(0x0020, 0x0032, "DS", b"0\\0\\1e300"),
        ),
        (
            "dicom_rescale_slope_zero",
            dcm_el(0x0028, 0x1053, "DS", b"0"),
        ),
    ] {
        folder(
            c,
            Kind::BadGeometry,
            name,
            vec![
                (
                    String::from("s0.dcm"),
                    Entry::File(dcm_slice(0, series, std::slice::from_ref(&el))),
                ),
                (
                    String::from("s1.dcm"),
                    Entry::File(dcm_slice(1, series, &[el])),
                ),
            ],
        )?;
    }
    // Cycle: sequences nested far deeper than any real file.
    let mut nested = dcm_el(0x0008, 0x0100, "SH", b"X");
    for _ in 0..200 {
        nested = dcm_undefined(0x0008, 0x1140, "SQ", &[nested]);
    }
    let mut e = dcm_slice_attributes(0.0, series, &[]);
    e.insert(3, nested);
    e.push(dcm_native(&dcm_pixels(0)));
    one(
        c,
        Kind::Cycle,
        "dicom_nested_200",
        dcm_file(CT_IMAGE, EXPLICIT_LE, &e),
    )?;
    // Out of range: DICOMDIR records to missing files or outside the folder, offset tables.
    let mut missing: Files = (0..2)
        .map(|k| (format!("IMG/S{k}"), Entry::File(dcm_slice(k, series, &[]))))
        .collect();
    missing.push((
        "DICOMDIR".into(),
        Entry::File(dicomdir(&["S0", "S1", "S9"])),
    ));
    c.add(
        r,
        Kind::OutOfRange,
        "dicom_dicomdir_missing_file",
        missing,
        "DICOMDIR",
    )?;
    c.one(
        r,
        Kind::OutOfRange,
        "dicom_dicomdir_escapes",
        "DICOMDIR",
        dicomdir(&["..", "etc"]),
    )?;
    c.one(
        r,
        Kind::OutOfRange,
        "dicom_dicomdir_no_records",
        "DICOMDIR",
        dcm_file("1.2.840.10008.1.3.10", EXPLICIT_LE, &[]),
    )?;
    one(c, Kind::OutOfRange, "dicom_offset_table_beyond", {
        // Two frames placed 2 mm apart (SpacingBetweenSlices), so the offset table is read.
        let mut e = dcm_slice_attributes(
            0.0,
            series,
            &[
                dcm_el(0x0018, 0x0088, "DS", b"2"),
                dcm_el(0x0028, 0x0008, "IS", b"2"),
            ],
        );
        let frame = rle_frame(&dcm_pixels(0));
        let table: Vec<u8> = [0u32, 99_999]
            .iter()
            .flat_map(|x| x.to_le_bytes())
            .collect();
        e.push(dcm_undefined(
            0x7FE0,
            0x0010,
            "OB",
            &[table, frame.clone(), frame],
        ));
        dcm_file(CT_IMAGE, "1.2.840.10008.1.2.5", &e)
    })?;
    // Not text, or text where numbers belong.
    one(
        c,
        Kind::NonUtf8,
        "dicom_random_after_magic",
        cat(&[&[0u8; 128], b"DICM", &junk, &junk]),
    )?;
    one(c, Kind::NonUtf8, "dicom_no_magic", junk.repeat(8))?;
    one(
        c,
        Kind::LongLine,
        "dicom_long_position",
        dcm_slice(
            0,
            series,
            &[dcm_el(
                0x0020,
                0x0032,
                "UT",
                "1\\".repeat(1 << 20).as_bytes(),
            )],
        ),
    )?;
    one(
        c,
        Kind::LongLine,
        "dicom_long_spacing",
        dcm_slice(
            0,
            series,
            &[cat(&[
                &[0x28, 0x00, 0x30, 0x00],
                b"UN",
                &[0, 0],
                &(4u32 << 20).to_le_bytes(),
                "9".repeat(4 << 20).as_bytes(),
            ])],
        ),
    )?;
    c.special(r, "dicom_special", "x.dcm")?;
    Ok(())
}

/// The multi-frame file of [`dcm_cases`] from its elements.
fn mf_file_bytes(elements: &[Vec<u8>]) -> Vec<u8> {
    dcm_file("1.2.840.10008.5.1.4.1.1.2.1", EXPLICIT_LE, elements)
}
