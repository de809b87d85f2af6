//! Hostile-corpus cases of the MetaImage, VTK image data and TIFF readers.
//!
//! Valid base files are written field by field from the formats' specifications (seed:
//! MetaIO's MetaImage documentation; VTK file formats, "Simple Legacy Formats" and "XML File
//! Formats" ImageData; TIFF 6.0, baseline greyscale, section 2), on the corpus's 5×4×3
//! gradient; each damaged case changes one thing the specification forbids.

use super::{
    Corpus, Entry, Expect, Files, Kind, Reader, ReplaceFirst, b64, cat, f32s_le, find, gradient,
    u8s, zlib,
};

fn file(name: &str, bytes: Vec<u8>) -> (String, Entry) {
    (name.to_string(), Entry::File(bytes))
}

// ---- MetaImage ---------------------------------------------------------------------------------

/// A MetaImage header for the 5×4×3 volume; `extra` lines go before `DimSize`.
fn mhd(ty: &str, extra: &str, data_file: &str) -> String {
    format!(
        "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\n\
         {extra}DimSize = 5 4 3\nElementSpacing = 1 1 1\nOffset = 0 0 0\n\
         ElementType = {ty}\nElementDataFile = {data_file}\n"
    )
}

pub(super) fn metaimage_cases(c: &mut Corpus) -> std::io::Result<()> {
    let r = Reader::MetaImage;
    let g = gradient();
    let raw = u8s(&g);
    let head = mhd("MET_UCHAR", "", "LOCAL");
    let mha = cat(&[head.as_bytes(), &raw]);
    let be16: Vec<u8> = g.iter().flat_map(|&x| (x as i16).to_be_bytes()).collect();
    let z = zlib(&f32s_le(&g));
    let zhead = mhd(
        "MET_FLOAT",
        &format!("CompressedData = True\nCompressedDataSize = {}\n", z.len()),
        "LOCAL",
    );
    let zmha = cat(&[zhead.as_bytes(), &z]);
    c.valid(r, "mha_u8", "v.mha", mha.clone())?;
    c.valid(
        r,
        "mha_i16_msb",
        "v.mha",
        cat(&[
            mhd("MET_SHORT", "", "LOCAL")
                .replace("ByteOrderMSB = False", "ByteOrderMSB = True")
                .as_bytes(),
            &be16,
        ]),
    )?;
    c.valid(r, "mha_zlib", "v.mha", zmha.clone())?;
    c.valid(
        r,
        "mha_oriented",
        "v.mha",
        cat(&[
            mhd(
                "MET_UCHAR",
                "TransformMatrix = 0 1 0 -1 0 0 0 0 1\nAnatomicalOrientation = ARI\n",
                "LOCAL",
            )
            .as_bytes(),
            &raw,
        ]),
    )?;
    c.add(
        r,
        Kind::Valid,
        "mhd_pattern",
        vec![
            file("v.mhd", mhd("MET_UCHAR", "", "s%d.raw 0 2 1").into_bytes()),
            file("s0.raw", raw[..20].to_vec()),
            file("s1.raw", raw[20..40].to_vec()),
            file("s2.raw", raw[40..].to_vec()),
        ],
        "v.mhd",
    )?
    .expect = Expect::Renders;
    let four = mhd("MET_UCHAR", "", "LOCAL")
        .replace("NDims = 3", "NDims = 4")
        .replace("DimSize = 5 4 3", "DimSize = 5 4 3 2")
        .replace("ElementSpacing = 1 1 1", "ElementSpacing = 1 1 1 0.5")
        .replace("Offset = 0 0 0", "Offset = 0 0 0 0");
    let four_data = cat(&[&raw, &raw.iter().map(|x| 16 - x).collect::<Vec<u8>>()]);
    c.valid(r, "mha_4d", "v.mha", cat(&[four.as_bytes(), &four_data]))?;
    // Truncations inside the data (raw, then zlib).
    c.truncations(r, "mha_raw", "v.mha", &mha, &[head.len()..mha.len()], 6)?;
    c.truncations(r, "mha_zlib", "v.mha", &zmha, &[zhead.len()..zmha.len()], 6)?;
    c.add(
        r,
        Kind::Truncated,
        "mhd_data_cut",
        vec![
            file("v.mhd", mhd("MET_UCHAR", "", "v.raw").into_bytes()),
            file("v.raw", raw[..37].to_vec()),
        ],
        "v.mhd",
    )?;
    let lying: Vec<(&str, Kind, Vec<u8>)> = vec![
        (
            "dims_larger",
            Kind::LyingHeader,
            mha.replace_first("DimSize = 5 4 3", "DimSize = 5 4 30"),
        ),
        (
            "dims_smaller",
            Kind::LyingHeader,
            mha.replace_first("DimSize = 5 4 3", "DimSize = 5 4 2"),
        ),
        (
            "type_larger",
            Kind::LyingHeader,
            mha.replace_first("MET_UCHAR", "MET_DOUBLE"),
        ),
        (
            "type_string",
            Kind::LyingHeader,
            mha.replace_first("MET_UCHAR", "MET_STRING"),
        ),
        (
            "type_i64",
            Kind::LyingHeader,
            mha.replace_first("MET_UCHAR", "MET_LONG_LONG"),
        ),
        (
            "ndims_5",
            Kind::LyingHeader,
            mha.replace_first("NDims = 3", "NDims = 5"),
        ),
        (
            "dims_count",
            Kind::LyingHeader,
            mha.replace_first("DimSize = 5 4 3", "DimSize = 5 4"),
        ),
        (
            "channels_3",
            Kind::LyingHeader,
            mha.replace_first("NDims = 3\n", "NDims = 3\nElementNumberOfChannels = 3\n"),
        ),
        (
            "object_mesh",
            Kind::LyingHeader,
            mha.replace_first("ObjectType = Image", "ObjectType = Mesh"),
        ),
        (
            "no_data_file_line",
            Kind::LyingHeader,
            head.replace("ElementDataFile = LOCAL\n", "").into_bytes(),
        ),
        (
            "ascii_data",
            Kind::LyingHeader,
            mha.replace_first("BinaryData = True", "BinaryData = False"),
        ),
        (
            "compressed_size_larger",
            Kind::LyingHeader,
            zmha.replace_first("CompressedDataSize = ", "CompressedDataSize = 9"),
        ),
        (
            "dims_overflow",
            Kind::Overflow,
            mha.replace_first(
                "DimSize = 5 4 3",
                "DimSize = 1099511627776 1099511627776 1099511627776",
            ),
        ),
        (
            "dims_u64max",
            Kind::Overflow,
            mha.replace_first("DimSize = 5 4 3", "DimSize = 18446744073709551615 1 1"),
        ),
        (
            "zlib_dims_huge",
            Kind::Overflow,
            zmha.replace_first("DimSize = 5 4 3", "DimSize = 5000 4000 3000"),
        ),
        (
            "headersize_1e15",
            Kind::HugeSkip,
            mha.replace_first("NDims = 3\n", "NDims = 3\nHeaderSize = 1000000000000000\n"),
        ),
        (
            "headersize_i64max",
            Kind::HugeSkip,
            mha.replace_first(
                "NDims = 3\n",
                "NDims = 3\nHeaderSize = 9223372036854775807\n",
            ),
        ),
        (
            "zlib_garbage",
            Kind::BadStream,
            cat(&[
                zhead.as_bytes(),
                &z.iter().map(|b| b ^ 0xa5).collect::<Vec<u8>>(),
            ]),
        ),
        (
            "zlib_of_raw",
            Kind::BadStream,
            cat(&[
                zhead
                    .replace(
                        &format!("CompressedDataSize = {}", z.len()),
                        "CompressedDataSize = 240",
                    )
                    .as_bytes(),
                &f32s_le(&g),
            ]),
        ),
        ("zlib_bomb", Kind::BadStream, {
            let bomb = zlib(&vec![0u8; 64 << 20]);
            cat(&[
                mhd(
                    "MET_FLOAT",
                    &format!(
                        "CompressedData = True\nCompressedDataSize = {}\n",
                        bomb.len()
                    ),
                    "LOCAL",
                )
                .as_bytes(),
                &bomb,
            ])
        }),
        (
            "spacing_zero",
            Kind::BadGeometry,
            mha.replace_first("ElementSpacing = 1 1 1", "ElementSpacing = 1 0 1"),
        ),
        (
            "spacing_nan",
            Kind::BadGeometry,
            mha.replace_first("ElementSpacing = 1 1 1", "ElementSpacing = nan 1 1"),
        ),
        (
            "offset_1e30",
            Kind::BadGeometry,
            mha.replace_first("Offset = 0 0 0", "Offset = 1e30 0 0"),
        ),
        (
            "transform_singular",
            Kind::BadGeometry,
            mha.replace_first(
                "NDims = 3\n",
                "NDims = 3\nTransformMatrix = 1 0 0 1 0 0 0 0 1\n",
            ),
        ),
        (
            "non_utf8",
            Kind::NonUtf8,
            super::replace_bytes(&mha, "NDims", b"ND\xffms"),
        ),
        (
            "long_line",
            Kind::LongLine,
            cat(&[
                b"ObjectType = ",
                "I".repeat(4 << 20).as_bytes(),
                b"\n",
                &mha,
            ]),
        ),
    ];
    for (n, kind, bytes) in lying {
        c.one(r, kind, &format!("mha_{n}"), "v.mha", bytes)?;
    }
    let detached: Vec<(&str, Kind, Files)> = vec![
        (
            "missing_data_file",
            Kind::SpecialFile,
            vec![file("v.mhd", mhd("MET_UCHAR", "", "gone.raw").into_bytes())],
        ),
        (
            "data_devzero",
            Kind::SpecialFile,
            vec![
                file("v.mhd", mhd("MET_UCHAR", "", "z.raw").into_bytes()),
                ("z.raw".into(), Entry::Link("/dev/zero".into())),
            ],
        ),
        (
            "data_fifo",
            Kind::SpecialFile,
            vec![
                file("v.mhd", mhd("MET_UCHAR", "", "p.raw").into_bytes()),
                ("p.raw".into(), Entry::Fifo),
            ],
        ),
        (
            "pattern_missing_slice",
            Kind::OutOfRange,
            vec![
                file("v.mhd", mhd("MET_UCHAR", "", "s%d.raw 0 2 1").into_bytes()),
                file("s0.raw", raw[..20].to_vec()),
                file("s1.raw", raw[20..40].to_vec()),
            ],
        ),
        (
            "list_short",
            Kind::LyingHeader,
            vec![
                file(
                    "v.mhd",
                    mhd("MET_UCHAR", "", "LIST\na.raw\nb.raw").into_bytes(),
                ),
                file("a.raw", raw[..20].to_vec()),
                file("b.raw", raw[20..40].to_vec()),
            ],
        ),
        (
            "headersize_end_short",
            Kind::HugeSkip,
            vec![
                file(
                    "v.mhd",
                    mhd("MET_UCHAR", "HeaderSize = -1\n", "v.raw").into_bytes(),
                ),
                file("v.raw", raw[..50].to_vec()),
            ],
        ),
    ];
    for (n, kind, entries) in detached {
        c.add(r, kind, &format!("mhd_{n}"), entries, "v.mhd")?;
    }
    c.special(r, "mha_special", "x.mha")?;
    Ok(())
}

// ---- VTK image data ------------------------------------------------------------------------

/// A `.vti` of the gradient as `Float32` point data named `g`; `array` is the `DataArray`
/// element (with its data), `compressor` the VTKFile attribute (may be empty).
fn vti(compressor: &str, array: &str, appended: &[u8]) -> Vec<u8> {
    let mut out = format!(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"ImageData\" version=\"1.0\" \
         byte_order=\"LittleEndian\" header_type=\"UInt32\"{compressor}>\n\
         <ImageData WholeExtent=\"0 4 0 3 0 2\" Origin=\"0 0 0\" Spacing=\"1 1 1\">\n\
         <Piece Extent=\"0 4 0 3 0 2\">\n<PointData Scalars=\"g\">\n{array}\n</PointData>\n\
         </Piece>\n</ImageData>\n"
    )
    .into_bytes();
    if !appended.is_empty() {
        out.extend_from_slice(b"<AppendedData encoding=\"raw\">\n_");
        out.extend_from_slice(appended);
        out.extend_from_slice(b"\n</AppendedData>\n");
    }
    out.extend_from_slice(b"</VTKFile>\n");
    out
}

fn legacy_points(binary: bool) -> Vec<u8> {
    let g = gradient();
    let head = format!(
        "# vtk DataFile Version 3.0\nhostile corpus\n{}\nDATASET STRUCTURED_POINTS\n\
         DIMENSIONS 5 4 3\nORIGIN 0 0 0\nSPACING 1 1 1\nPOINT_DATA 60\n\
         SCALARS g float 1\nLOOKUP_TABLE default\n",
        if binary { "BINARY" } else { "ASCII" }
    );
    let data = if binary {
        g.iter().flat_map(|&x| (x as f32).to_be_bytes()).collect()
    } else {
        super::ascii_values(&g)
    };
    cat(&[head.as_bytes(), &data])
}

pub(super) fn vtk_image_cases(c: &mut Corpus) -> std::io::Result<()> {
    let r = Reader::VtkImage;
    let g = gradient();
    let f32le = f32s_le(&g);
    let mut block = (f32le.len() as u32).to_le_bytes().to_vec();
    block.extend_from_slice(&f32le);
    let ascii = vti(
        "",
        &format!(
            "<DataArray type=\"Float32\" Name=\"g\" format=\"ascii\">{}</DataArray>",
            String::from_utf8_lossy(&super::ascii_values(&g))
        ),
        &[],
    );
    let binary = vti(
        "",
        &format!(
            "<DataArray type=\"Float32\" Name=\"g\" format=\"binary\">{}</DataArray>",
            b64(&block)
        ),
        &[],
    );
    let appended = vti(
        "",
        "<DataArray type=\"Float32\" Name=\"g\" format=\"appended\" offset=\"0\"/>",
        &block,
    );
    let z = zlib(&f32le);
    let mut zhead = Vec::new();
    for w in [1u32, 240, 240, z.len() as u32] {
        zhead.extend(w.to_le_bytes());
    }
    let zlib_vti = vti(
        " compressor=\"vtkZLibDataCompressor\"",
        &format!(
            "<DataArray type=\"Float32\" Name=\"g\" format=\"binary\">{}{}</DataArray>",
            b64(&zhead),
            b64(&z)
        ),
        &[],
    );
    c.valid(r, "vti_ascii", "v.vti", ascii.clone())?;
    c.valid(r, "vti_binary", "v.vti", binary.clone())?;
    c.valid(r, "vti_appended", "v.vti", appended.clone())?;
    c.valid(r, "vti_zlib", "v.vti", zlib_vti.clone())?;
    c.valid(r, "vtk_points_ascii", "v.vtk", legacy_points(false))?;
    let lb = legacy_points(true);
    c.valid(r, "vtk_points_binary", "v.vtk", lb.clone())?;
    c.valid(
        r,
        "vtk_rectilinear",
        "v.vtk",
        legacy_points(false)
            .replace_first("STRUCTURED_POINTS", "RECTILINEAR_GRID")
            .replace_first(
                "ORIGIN 0 0 0\nSPACING 1 1 1\n",
                "X_COORDINATES 5 float\n0 1 2 4 8\nY_COORDINATES 4 double\n0 0.5 1 1.5\n\
                 Z_COORDINATES 3 float\n-1 0 1\n",
            ),
    )?;
    let tail = find(&appended, "raw\">\n_").end;
    c.truncations(
        r,
        "vti_appended",
        "v.vti",
        &appended,
        &[tail..tail + block.len()],
        6,
    )?;
    let data_at = find(&lb, "LOOKUP_TABLE default\n").end;
    c.truncations(r, "vtk_points", "v.vtk", &lb, &[data_at..lb.len()], 5)?;
    let bad: Vec<(&str, &str, Kind, Vec<u8>)> = vec![
        ("extent_larger", "v.vti", Kind::LyingHeader, binary.replace_first("0 4 0 3 0 2", "0 4 0 3 0 9").replace_first("0 4 0 3 0 2", "0 4 0 3 0 9")),
        ("piece_partial", "v.vti", Kind::LyingHeader, binary.replace_first("<Piece Extent=\"0 4", "<Piece Extent=\"1 4")),
        ("extent_reversed", "v.vti", Kind::LyingHeader, binary.replace_first("0 4 0 3 0 2", "4 0 0 3 0 2")),
        ("type_int64", "v.vti", Kind::LyingHeader, ascii.replace_first("Float32", "Int64")),
        ("no_arrays", "v.vti", Kind::LyingHeader, vti("", "", &[])),
        ("header_lies", "v.vti", Kind::LyingHeader, {
            // The block header says 241 bytes for 240.
            let mut x = appended.clone();
            x[find(&appended, "raw\">\n_").end] = 241;
            x
        }),
        ("polydata", "v.vti", Kind::LyingHeader, ascii.replace_first("ImageData\" version", "PolyData\" version")),
        ("extent_overflow", "v.vti", Kind::Overflow, binary.replace_first("0 4 0 3 0 2", "0 999999999999 0 999999999999 0 999999").replace_first("0 4 0 3 0 2", "0 999999999999 0 999999999999 0 999999")),
        ("zlib_garbage", "v.vti", Kind::BadStream, zlib_vti.replace_first(&b64(&z)[..8], "AAAAAAAA")),
        ("lz4_of_zlib", "v.vti", Kind::BadStream, zlib_vti.replace_first("vtkZLibDataCompressor", "vtkLZ4DataCompressor")),
        ("base64_broken", "v.vti", Kind::BadStream, binary.replace_first(&b64(&block)[..6], "!!!!!!")),
        ("spacing_zero", "v.vti", Kind::BadGeometry, ascii.replace_first("Spacing=\"1 1 1\"", "Spacing=\"1 0 1\"")),
        ("origin_1e30", "v.vti", Kind::BadGeometry, ascii.replace_first("Origin=\"0 0 0\"", "Origin=\"1e30 0 0\"")),
        ("direction_singular", "v.vti", Kind::BadGeometry, ascii.replace_first("Spacing=\"1 1 1\"", "Spacing=\"1 1 1\" Direction=\"1 0 0 1 0 0 0 0 1\"")),
        ("non_utf8", "v.vti", Kind::NonUtf8, cat(&[&ascii[..20], b"\xff\xfe", &ascii[20..]])),
        ("long_line", "v.vti", Kind::LongLine, ascii.replace_first("Spacing=\"1 1 1\"", &format!("Spacing=\"{}\"", "1 ".repeat(2 << 20)))),
        ("vtk_points_dims_larger", "v.vtk", Kind::LyingHeader, lb.replace_first("DIMENSIONS 5 4 3", "DIMENSIONS 5 4 30")),
        ("vtk_points_count_lies", "v.vtk", Kind::LyingHeader, lb.replace_first("POINT_DATA 60", "POINT_DATA 61")),
        ("vtk_dims_overflow", "v.vtk", Kind::Overflow, lb.replace_first("DIMENSIONS 5 4 3", "DIMENSIONS 4294967296 4294967296 4294967296")),
        ("vtk_rectilinear_decreasing", "v.vtk", Kind::BadGeometry, legacy_points(false)
            .replace_first("STRUCTURED_POINTS", "RECTILINEAR_GRID")
            .replace_first("ORIGIN 0 0 0\nSPACING 1 1 1\n", "X_COORDINATES 5 float\n0 1 2 1 0\nY_COORDINATES 4 float\n0 1 2 3\nZ_COORDINATES 3 float\n0 1 2\n")),
        ("vtk_spacing_nan", "v.vtk", Kind::BadGeometry, lb.replace_first("SPACING 1 1 1", "SPACING nan 1 1")),
    ];
    for (n, name, kind, bytes) in bad {
        c.one(r, kind, &format!("vtkimg_{n}"), name, bytes)?;
    }
    c.special(r, "vti_special", "x.vti")?;
    Ok(())
}

// ---- TIFF ---------------------------------------------------------------------------------------

/// One page of a baseline greyscale TIFF: `w`×`h` samples of `bits` (format 1 unsigned, 2
/// signed, 3 float), one strip, uncompressed unless `compression` says otherwise.
struct Page {
    w: u32,
    h: u32,
    bits: u16,
    format: u16,
    compression: u16,
    samples: u16,
    data: Vec<u8>,
}

/// A little-endian TIFF of `pages` (IFDs first, then the strips), and the byte range of
/// each page's strip.
fn tiff(pages: &[Page]) -> (Vec<u8>, Vec<std::ops::Range<usize>>) {
    const ENTRIES: usize = 10;
    let ifd_len = 2 + ENTRIES * 12 + 4;
    let ifds_at = 8;
    let mut data_at = ifds_at + pages.len() * ifd_len;
    let mut out = b"II*\0".to_vec();
    out.extend((ifds_at as u32).to_le_bytes());
    let mut ranges = Vec::new();
    for (p, page) in pages.iter().enumerate() {
        let next = if p + 1 == pages.len() {
            0
        } else {
            ifds_at + (p + 1) * ifd_len
        };
        let entries: [(u16, u16, u32); ENTRIES] = [
            (256, 4, page.w),
            (257, 4, page.h),
            (258, 3, u32::from(page.bits)),
            (259, 3, u32::from(page.compression)),
            (262, 3, 1),
            (273, 4, data_at as u32),
            (277, 3, u32::from(page.samples)),
            (278, 4, page.h),
            (279, 4, page.data.len() as u32),
            (339, 3, u32::from(page.format)),
        ];
        out.extend((ENTRIES as u16).to_le_bytes());
        for (tag, ty, value) in entries {
            out.extend(tag.to_le_bytes());
            out.extend(ty.to_le_bytes());
            out.extend(1u32.to_le_bytes());
            if ty == 3 {
                out.extend((value as u16).to_le_bytes());
                out.extend([0, 0]);
            } else {
                out.extend(value.to_le_bytes());
            }
        }
        out.extend((next as u32).to_le_bytes());
        ranges.push(data_at..data_at + page.data.len());
        data_at += page.data.len();
    }
    for page in pages {
        out.extend_from_slice(&page.data);
    }
    (out, ranges)
}

/// The gradient as 3 pages of `bits`-bit samples (format 1 unsigned, 3 float).
fn gradient_pages(bits: u16, format: u16) -> Vec<Page> {
    let g = gradient();
    g.chunks(20)
        .map(|slice| Page {
            w: 5,
            h: 4,
            bits,
            format,
            compression: 1,
            samples: 1,
            data: match (bits, format) {
                (8, _) => u8s(slice),
                (16, _) => slice
                    .iter()
                    .flat_map(|&x| (x as u16).to_le_bytes())
                    .collect(),
                _ => f32s_le(slice),
            },
        })
        .collect()
}

pub(super) fn tiff_cases(c: &mut Corpus) -> std::io::Result<()> {
    let r = Reader::Tiff;
    let (u8tif, ranges) = tiff(&gradient_pages(8, 1));
    let (f32tif, _) = tiff(&gradient_pages(32, 3));
    let (u16tif, _) = tiff(&gradient_pages(16, 1));
    c.valid(r, "tiff_u8", "v.tif", u8tif.clone())?;
    c.valid(r, "tiff_f32", "v.tif", f32tif)?;
    c.valid(r, "tiff_u16", "v.tiff", u16tif)?;
    let slices: Files = gradient_pages(8, 1)
        .into_iter()
        .enumerate()
        .map(|(k, p)| file(&format!("s_{k:03}.tif"), tiff(&[p]).0))
        .collect();
    c.add(r, Kind::Valid, "tiff_slices", slices, "s_%03d.tif")?
        .expect = Expect::Renders;
    // Two pages (5×4×2). Also the corpus's last valid case: the viewer test opens a 5×4×3
    // gradient after the corpus and waits for a new frame, which an identical view (the
    // slices above are that same grid) would not need.
    c.valid(
        r,
        "tiff_two_pages",
        "v.tif",
        tiff(&gradient_pages(8, 1)[..2]).0,
    )?;
    let strips = ranges.clone();
    c.truncations(r, "tiff", "v.tif", &u8tif, &strips, 6)?;
    c.truncations(r, "tiff_ifd", "v.tif", &u8tif, &[9..ranges[0].start], 5)?;
    let page = |f: &dyn Fn(&mut Page)| {
        let mut pages = gradient_pages(8, 1);
        f(&mut pages[1]);
        tiff(&pages).0
    };
    let bad: Vec<(&str, Kind, Vec<u8>)> = vec![
        (
            "page_wider",
            Kind::LyingHeader,
            page(&|p| {
                p.w = 10;
                p.h = 2;
            }),
        ),
        ("page_size_lies", Kind::LyingHeader, page(&|p| p.w = 50)),
        ("bits_12", Kind::LyingHeader, page(&|p| p.bits = 12)),
        ("rgb", Kind::LyingHeader, page(&|p| p.samples = 3)),
        (
            "page_type_differs",
            Kind::LyingHeader,
            page(&|p| {
                p.bits = 16;
                p.data = p
                    .data
                    .iter()
                    .flat_map(|&x| u16::from(x).to_le_bytes())
                    .collect();
            }),
        ),
        (
            "size_overflow",
            Kind::Overflow,
            page(&|p| {
                p.w = u32::MAX;
                p.h = u32::MAX;
            }),
        ),
        (
            "deflate_garbage",
            Kind::BadStream,
            page(&|p| p.compression = 8),
        ),
        ("lzw_garbage", Kind::BadStream, page(&|p| p.compression = 5)),
        ("jpeg", Kind::BadStream, page(&|p| p.compression = 7)),
        ("not_tiff", Kind::NonUtf8, cat(&[b"II*\0", &[0xff; 64]])),
        (
            "text",
            Kind::LongLine,
            "II*\0 not really".repeat(1 << 18).into_bytes(),
        ),
    ];
    for (n, kind, bytes) in bad {
        c.one(r, kind, &format!("tiff_{n}"), "v.tif", bytes)?;
    }
    // The last page's "next IFD" points back at the first: a cycle.
    let mut cyc = u8tif.clone();
    let ifd_len = 2 + 10 * 12 + 4;
    let last_next = 8 + 3 * ifd_len - 4;
    cyc[last_next..last_next + 4].copy_from_slice(&8u32.to_le_bytes());
    c.one(r, Kind::Cycle, "tiff_ifd_cycle", "v.tif", cyc)?;
    // A strip offset past the end of the file.
    let mut far = u8tif.clone();
    let strip_offset = 8 + 2 + 5 * 12 + 8;
    far[strip_offset..strip_offset + 4].copy_from_slice(&u32::MAX.to_le_bytes());
    c.one(r, Kind::OutOfRange, "tiff_strip_offset_far", "v.tif", far)?;
    // Numbered slices of different sizes.
    let mut pages = gradient_pages(8, 1);
    pages[2].w = 4;
    pages[2].data.truncate(16);
    let slices: Files = pages
        .into_iter()
        .enumerate()
        .map(|(k, p)| file(&format!("s_{k:03}.tif"), tiff(&[p]).0))
        .collect();
    c.add(
        r,
        Kind::LyingHeader,
        "tiff_slices_sizes_differ",
        slices,
        "s_*.tif",
    )?;
    c.special(r, "tiff_special", "x.tif")?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::spread;
    use super::*;

    #[test]
    fn the_hand_made_tiff_has_its_strips_where_the_directories_say() {
        let (t, ranges) = tiff(&gradient_pages(8, 1));
        assert_eq!(&t[..4], b"II*\0");
        assert_eq!(ranges.len(), 3);
        assert_eq!(ranges[2].end, t.len());
        // The first strip offset (tag 273) points at the first range.
        let entry = 8 + 2 + 5 * 12;
        assert_eq!(u16::from_le_bytes([t[entry], t[entry + 1]]), 273);
        let at = u32::from_le_bytes(t[entry + 8..entry + 12].try_into().unwrap());
        assert_eq!(at as usize, ranges[0].start);
        assert_eq!(&t[ranges[0].clone()], &u8s(&gradient())[..20]);
        // `spread` picks cuts inside the strips.
        assert!(
            spread(&ranges, 4)
                .iter()
                .all(|&c| ranges.iter().any(|r| r.contains(&c)))
        );
    }
}
