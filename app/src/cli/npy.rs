//! A minimal NumPy `.npy` (format version 1.0) writer and reader for 2D `float32` arrays,
//! used by `isoscope render --depth-out`.
//!
//! Layout (numpy `lib/format.py`): the magic `\x93NUMPY`, version bytes `1, 0`, a
//! little-endian `u16` header length, then an ASCII Python dict
//! `{'descr': '<f4', 'fortran_order': False, 'shape': (H, W), }` padded with spaces and a final
//! `\n` so that the data starts at a multiple of 64 bytes; then `H·W` little-endian `f32`,
//! row-major (C order), row 0 first.

use std::io::{Read, Write};

use anyhow::{Context as _, bail, ensure};

const MAGIC: &[u8; 6] = b"\x93NUMPY";

/// Writes a `(rows, cols)` float32 array in C order to `w`.
pub fn write_f32_2d(
    mut w: impl Write,
    rows: usize,
    cols: usize,
    data: &[f32],
) -> std::io::Result<()> {
    assert_eq!(
        data.len(),
        rows * cols,
        "npy: data length must be rows·cols"
    );
    let mut header =
        format!("{{'descr': '<f4', 'fortran_order': False, 'shape': ({rows}, {cols}), }}");
    // magic (6) + version (2) + length (2) + header + '\n' ≡ 0 (mod 64)
    let unpadded = 10 + header.len() + 1;
    header.push_str(&" ".repeat(unpadded.next_multiple_of(64) - unpadded));
    header.push('\n');
    let len = u16::try_from(header.len()).expect("npy header is short");
    w.write_all(MAGIC)?;
    w.write_all(&[1, 0])?;
    w.write_all(&len.to_le_bytes())?;
    w.write_all(header.as_bytes())?;
    let mut bytes = Vec::with_capacity(data.len() * 4);
    for v in data {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    w.write_all(&bytes)?;
    w.flush()
}

/// Reads a version 1.0 `.npy` holding a 2D little-endian float32 C-order array:
/// `((rows, cols), data)`. Anything else is an error naming what differs.
pub fn read_f32_2d(mut r: impl Read) -> anyhow::Result<((usize, usize), Vec<f32>)> {
    let mut pre = [0u8; 10];
    r.read_exact(&mut pre)
        .context("npy: file shorter than its preamble")?;
    ensure!(&pre[..6] == MAGIC, "npy: bad magic {:?}", &pre[..6]);
    ensure!(
        pre[6] == 1 && pre[7] == 0,
        "npy: version {}.{} (expected 1.0)",
        pre[6],
        pre[7]
    );
    let len = u16::from_le_bytes([pre[8], pre[9]]) as usize;
    ensure!(
        (10 + len).is_multiple_of(16),
        "npy: data offset {} is not 16-byte aligned",
        10 + len
    );
    let mut header = vec![0u8; len];
    r.read_exact(&mut header).context("npy: header truncated")?;
    let header = std::str::from_utf8(&header).context("npy: header is not ASCII")?;
    ensure!(
        header.ends_with('\n'),
        "npy: header does not end with a newline"
    );
    let field = |key: &str| -> anyhow::Result<&str> {
        let at = header
            .find(&format!("'{key}':"))
            .with_context(|| format!("npy: header has no '{key}'"))?;
        Ok(header[at + key.len() + 3..].trim_start())
    };
    ensure!(
        field("descr")?.starts_with("'<f4'"),
        "npy: descr is not '<f4': {header}"
    );
    ensure!(
        field("fortran_order")?.starts_with("False"),
        "npy: fortran_order is not False"
    );
    let shape = field("shape")?;
    let Some(inner) = shape.strip_prefix('(').and_then(|s| s.split(')').next()) else {
        bail!("npy: malformed shape in {header}");
    };
    let dims: Vec<usize> = inner
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| {
            s.parse::<usize>()
                .with_context(|| format!("npy: bad shape entry {s:?}"))
        })
        .collect::<anyhow::Result<_>>()?;
    let [rows, cols] = dims[..] else {
        bail!("npy: shape {dims:?} is not 2D");
    };
    let count = rows.checked_mul(cols).context("npy: shape overflows")?;
    let mut bytes = Vec::new();
    r.read_to_end(&mut bytes)?;
    ensure!(
        bytes.len() == count * 4,
        "npy: {} data bytes for shape ({rows}, {cols}) which needs {}",
        bytes.len(),
        count * 4
    );
    let data = bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    Ok(((rows, cols), data))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_preserves_shape_values_and_infinities() {
        let data: Vec<f32> = (0..6 * 5)
            .map(|i| {
                if i % 7 == 3 {
                    f32::INFINITY
                } else {
                    i as f32 * 0.25 - 2.0
                }
            })
            .collect();
        let mut buf = Vec::new();
        write_f32_2d(&mut buf, 6, 5, &data).unwrap();
        // Header: magic, version 1.0, data 64-byte aligned, the exact dict numpy writes.
        assert_eq!(&buf[..8], b"\x93NUMPY\x01\x00");
        let len = u16::from_le_bytes([buf[8], buf[9]]) as usize;
        assert_eq!((10 + len) % 64, 0);
        let header = std::str::from_utf8(&buf[10..10 + len]).unwrap();
        assert!(header.starts_with("{'descr': '<f4', 'fortran_order': False, 'shape': (6, 5), }"));
        assert!(header.ends_with(" \n"));
        assert_eq!(buf.len(), 10 + len + 6 * 5 * 4);
        // Row-major little-endian: element (1, 2) is at index 7.
        let at = 10 + len + 7 * 4;
        assert_eq!(
            f32::from_le_bytes(buf[at..at + 4].try_into().unwrap()),
            data[7]
        );
        let ((r, c), back) = read_f32_2d(&buf[..]).unwrap();
        assert_eq!((r, c), (6, 5));
        assert_eq!(
            back.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            data.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
    }

    #[test]
    fn reader_rejects_truncated_and_foreign_files() {
        let mut buf = Vec::new();
        write_f32_2d(&mut buf, 2, 2, &[1.0; 4]).unwrap();
        assert!(
            read_f32_2d(&buf[..buf.len() - 1])
                .unwrap_err()
                .to_string()
                .contains("data bytes")
        );
        let mut f8 = buf.clone();
        let pos = f8.windows(3).position(|w| w == b"<f4").unwrap();
        f8[pos + 2] = b'8';
        assert!(
            read_f32_2d(&f8[..])
                .unwrap_err()
                .to_string()
                .contains("descr")
        );
        assert!(read_f32_2d(&b"PK\x03\x04"[..]).is_err());
    }
}
