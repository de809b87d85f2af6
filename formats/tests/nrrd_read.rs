//! NRRD reading across encodings, byte orders, skips, detached data and 4D series, against
//! voxel values computed independently in the test.

use std::io::Write;
use std::path::Path;

use formats::{Dataset, FormatError, OpenOptions};
use volume_core::RectilinearVolume;

fn value(i: usize) -> i32 {
    (i as i32 * 7919) % 2001 - 1000
}

fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    e.write_all(bytes).unwrap();
    e.finish().unwrap()
}

fn bzip2(bytes: &[u8]) -> Vec<u8> {
    let mut e = bzip2::write::BzEncoder::new(Vec::new(), bzip2::Compression::default());
    e.write_all(bytes).unwrap();
    e.finish().unwrap()
}

fn write(path: &Path, header: &str, data: &[u8]) {
    let mut bytes = header.as_bytes().to_vec();
    bytes.extend_from_slice(data);
    std::fs::write(path, bytes).unwrap();
}

fn volume(path: &Path) -> RectilinearVolume {
    match formats::open(path, &OpenOptions::default()).unwrap() {
        Dataset::Volume(v) => v,
        Dataset::Series(_) => panic!("volume expected"),
    }
}

fn assert_values(v: &RectilinearVolume, f: impl Fn(usize) -> f64) {
    let [nx, ny, nz] = v.dims();
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let idx = i + nx * (j + ny * k);
                assert_eq!(v.value_f64(i, j, k), f(idx), "voxel ({i},{j},{k})");
            }
        }
    }
}

const N: usize = 3 * 4 * 5;

#[test]
fn gzip_big_endian_short() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("a.nrrd");
    let data: Vec<u8> = (0..N)
        .flat_map(|i| (value(i) as i16).to_be_bytes())
        .collect();
    write(
        &p,
        "NRRD0004\ntype: short\ndimension: 3\nsizes: 3 4 5\nendian: big\nencoding: gz\nspacings: 0.5 1 2\n\n",
        &gzip(&data),
    );
    let v = volume(&p);
    assert_eq!(v.grid.uniform_spacing(), Some([0.5, 1.0, 2.0]));
    assert_values(&v, |i| f64::from(value(i) as i16));
}

#[test]
fn bzip2_little_endian_float() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("a.nrrd");
    let data: Vec<u8> = (0..N)
        .flat_map(|i| (value(i) as f32 * 0.25).to_le_bytes())
        .collect();
    write(
        &p,
        "NRRD0005\ntype: float\ndimension: 3\nsizes: 3 4 5\nendian: little\nencoding: bzip2\n\n",
        &bzip2(&data),
    );
    assert_values(&volume(&p), |i| f64::from(value(i) as f32 * 0.25));
}

#[test]
fn ascii_and_hex() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("a.nrrd");
    let text: Vec<String> = (0..N).map(|i| format!("{}", value(i))).collect();
    let body = text
        .chunks(3)
        .map(|c| c.join(" "))
        .collect::<Vec<_>>()
        .join("\n");
    write(
        &p,
        "NRRD0004\ntype: int\ndimension: 3\nsizes: 3 4 5\nencoding: text\n\n",
        body.as_bytes(),
    );
    let v = volume(&p);
    assert!(!v.data.is_shared());
    assert_values(&v, |i| f64::from(value(i)));

    let hex: String = (0..N)
        .flat_map(|i| (value(i) as u16).to_be_bytes())
        .map(|b| format!("{b:02x}"))
        .collect::<Vec<_>>()
        .chunks(16)
        .map(<[String]>::concat)
        .collect::<Vec<_>>()
        .join("\n");
    write(
        &p,
        "NRRD0004\ntype: ushort\ndimension: 3\nsizes: 3 4 5\nendian: big\nencoding: hex\n\n",
        hex.as_bytes(),
    );
    assert_values(&volume(&p), |i| f64::from(value(i) as u16));
}

#[test]
fn ascii_floats_with_nan_and_commas() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("a.nrrd");
    write(
        &p,
        "NRRD0001\ntype: double\ndimension: 3\nsizes: 2 1 2\nencoding: ascii\n\n",
        b"1.5, -2e3\nnan\n  0.1\n",
    );
    let v = volume(&p);
    assert_eq!(v.value_f64(0, 0, 0), 1.5);
    assert_eq!(v.value_f64(1, 0, 0), -2000.0);
    assert!(v.value_f64(0, 0, 1).is_nan());
    assert_eq!(v.value_f64(1, 0, 1), 0.1);
}

#[test]
fn detached_with_line_and_byte_skip_and_data_at_end() {
    let dir = tempfile::tempdir().unwrap();
    let raw: Vec<u8> = (0..N)
        .flat_map(|i| (value(i) as i16).to_le_bytes())
        .collect();
    let mut data = b"P5 junk line\nsecond line\nABC".to_vec();
    data.extend_from_slice(&raw);
    std::fs::write(dir.path().join("d.raw"), &data).unwrap();
    let h = dir.path().join("d.nhdr");
    std::fs::write(
        &h,
        "NRRD0004\ntype: int16\ndimension: 3\nsizes: 3 4 5\nendian: little\nencoding: raw\n\
         data file: d.raw\nline skip: 2\nbyte skip: 3\n",
    )
    .unwrap();
    assert_values(&volume(&h), |i| f64::from(value(i) as i16));
    std::fs::write(
        &h,
        "NRRD0004\ntype: int16\ndimension: 3\nsizes: 3 4 5\nendian: little\nencoding: raw\n\
         data file: ./d.raw\nbyte skip: -1\n",
    )
    .unwrap();
    assert_values(&volume(&h), |i| f64::from(value(i) as i16));
    // Attached, data at the end, with junk between header and data.
    let p = dir.path().join("e.nrrd");
    let mut body = b"some junk".to_vec();
    body.extend_from_slice(&raw);
    write(
        &p,
        "NRRD0004\ntype: int16\ndimension: 3\nsizes: 3 4 5\nendian: little\nencoding: raw\nbyte skip: -1\n\n",
        &body,
    );
    assert_values(&volume(&p), |i| f64::from(value(i) as i16));
}

#[test]
fn list_and_pattern_of_slice_files() {
    let dir = tempfile::tempdir().unwrap();
    let slice = 3 * 4;
    for z in 0..5 {
        let bytes: Vec<u8> = (z * slice..(z + 1) * slice)
            .map(|i| value(i) as u8)
            .collect();
        std::fs::write(
            dir.path().join(format!("s{:02}.raw", 2 * z + 1)),
            gzip(&bytes),
        )
        .unwrap();
    }
    let h = dir.path().join("p.nhdr");
    std::fs::write(
        &h,
        "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 3 4 5\nencoding: gzip\n\
         data file: s%02d.raw 1 9 2\n",
    )
    .unwrap();
    assert_values(&volume(&h), |i| f64::from(value(i) as u8));
    let names: String = (0..5).fold(String::new(), |mut acc, z| {
        use std::fmt::Write as _;
        let _ = writeln!(acc, "s{:02}.raw", 2 * z + 1);
        acc
    });
    std::fs::write(
        &h,
        format!(
            "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 3 4 5\nencoding: gzip\ndata file: LIST\n{names}"
        ),
    )
    .unwrap();
    assert_values(&volume(&h), |i| f64::from(value(i) as u8));
}

#[test]
fn four_d_raw_is_a_series_of_zero_copy_steps() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("t.nrrd");
    let steps = 4;
    let data: Vec<u8> = (0..N * steps)
        .flat_map(|i| (value(i) as f32).to_le_bytes())
        .collect();
    // Header padded to a multiple of 4 bytes so the map can be viewed as f32 in place.
    let mut header = String::from(
        "NRRD0004\ntype: float\ndimension: 4\nsizes: 3 4 5 4\nendian: little\nencoding: raw\n\
         kinds: domain domain domain time\nspacings: 1 1 1 0.5\naxis mins: 0 0 0 2\n",
    );
    let mut pad = (4 - (header.len() + 1) % 4) % 4;
    if pad == 1 {
        pad = 5;
    }
    if pad > 0 {
        header.push_str(&"#".repeat(pad - 1));
        header.push('\n');
    }
    header.push('\n');
    write(&p, &header, &data);
    let Dataset::Series(ts) = formats::open(&p, &OpenOptions::default()).unwrap() else {
        panic!("series expected")
    };
    assert_eq!(ts.step_count(), steps);
    assert_eq!(ts.time_value(3), 2.0 + 1.5);
    for s in 0..steps {
        let v = ts.step(s).unwrap();
        if cfg!(target_endian = "little") {
            assert!(v.data.is_shared(), "step {s} should view the map");
        }
        assert_values(&v, |i| f64::from(value(i + s * N) as f32));
    }
}

#[test]
fn four_d_gzip_and_detached_step_files() {
    let dir = tempfile::tempdir().unwrap();
    let steps = 3;
    let all: Vec<u8> = (0..N * steps)
        .flat_map(|i| (value(i) as i16).to_be_bytes())
        .collect();
    let p = dir.path().join("g.nrrd");
    write(
        &p,
        "NRRD0004\ntype: short\ndimension: 4\nsizes: 3 4 5 3\nendian: big\nencoding: gzip\n\
         space dimension: 3\nspace directions: (1,0,0) (0,1,0) (0,0,1) none\n\n",
        &gzip(&all),
    );
    let Dataset::Series(ts) = formats::open(&p, &OpenOptions::default()).unwrap() else {
        panic!("series expected")
    };
    assert_values(&ts.step(2).unwrap(), |i| f64::from(value(i + 2 * N) as i16));
    assert_values(&ts.step(1).unwrap(), |i| f64::from(value(i + N) as i16));
    // One raw file per step through a LIST with subdim 3.
    let mut names = String::new();
    for s in 0..steps {
        let name = format!("step{s}.raw");
        std::fs::write(dir.path().join(&name), &all[s * N * 2..(s + 1) * N * 2]).unwrap();
        names.push_str(&name);
        names.push('\n');
    }
    let h = dir.path().join("l.nhdr");
    std::fs::write(
        &h,
        format!(
            "NRRD0004\ntype: short\ndimension: 4\nsizes: 3 4 5 3\nendian: big\nencoding: raw\ndata file: LIST 3\n{names}"
        ),
    )
    .unwrap();
    let Dataset::Series(ts) = formats::open(&h, &OpenOptions::default()).unwrap() else {
        panic!("series expected")
    };
    assert_eq!(ts.step_count(), 3);
    assert_values(&ts.step(2).unwrap(), |i| f64::from(value(i + 2 * N) as i16));
}

#[test]
fn leading_scalar_axis_is_dropped() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("s.nrrd");
    let data: Vec<u8> = (0..N).map(|i| value(i) as i8 as u8).collect();
    write(
        &p,
        "NRRD0004\ntype: signed char\ndimension: 4\nsizes: 1 3 4 5\nencoding: raw\nkinds: scalar domain domain domain\n\n",
        &data,
    );
    let v = volume(&p);
    assert_eq!(v.dims(), [3, 4, 5]);
    assert_values(&v, |i| f64::from(value(i) as i8));
}

#[test]
fn truncated_and_overlong_gzip_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("t.nrrd");
    let data: Vec<u8> = (0..N).map(|i| value(i) as u8).collect();
    let z = gzip(&data);
    let header = "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 3 4 5\nencoding: gzip\n\n";
    for cut in [z.len() - 4, z.len() / 2, 12] {
        write(&p, header, &z[..cut]);
        let e = formats::open(&p, &OpenOptions::default()).unwrap_err();
        assert!(
            matches!(
                &e,
                FormatError::Decode {
                    encoding: "gzip",
                    ..
                }
            ),
            "cut {cut}: {e}"
        );
    }
    let more: Vec<u8> = (0..=N).map(|i| value(i) as u8).collect();
    write(&p, header, &gzip(&more));
    let e = formats::open(&p, &OpenOptions::default()).unwrap_err();
    assert!(matches!(&e, FormatError::TooLong { .. }), "{e}");
}
