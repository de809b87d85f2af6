//! Pixel data: one frame at a time, from any supported transfer syntax to little-endian
//! samples, then to typed voxels.
//!
//! - Native data (implicit/explicit VR little endian, explicit big endian, deflated data set):
//!   a slice of the data set bytes, byte-swapped for big endian.
//! - Encapsulated data: the frame's fragments ([`frame_fragments`]: the basic offset table, one
//!   fragment per frame, or fragments grouped at each codestream start), then decoded here
//!   (RLE Lossless, PS3.5 Annex G; Deflated Image Frame Compression; Encapsulated
//!   Uncompressed) or by the pure-Rust `jpeg-decoder` (JPEG baseline, extended 8-bit,
//!   lossless) and `hayro-jpeg2000` (JPEG 2000). dicom-rs's own adapters are not used: they
//!   index past the end of short RLE segments and copy a JPEG of other dimensions into the
//!   frame (panics on hostile input).
//! - Every decoder checks the codestream's dimensions and precision against Rows, Columns and
//!   BitsAllocated before it decodes, and the decoded size is bounded by the codec's largest
//!   compression ratio ([`max_ratio`]), so a small fragment cannot allocate gigabytes.
//! - [`store`] masks each sample to BitsStored (at HighBit), sign-extends signed data, and
//!   optionally applies a rescale (slices of different rescales become `f32`).

use std::borrow::Cow;
use std::io::Read as _;
use std::ops::Range;
use std::path::Path;

use volume_core::{Voxel, VoxelType};

use super::file::{DicomFile, PixelCodec};
use super::scan::PixelValue;
use crate::error::FormatError;

/// How the samples of an image are stored (single sample per pixel).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(crate) struct PixelFormat {
    pub rows: usize,
    pub cols: usize,
    /// 8, 16 or 32 (integers), 32 or 64 (floats).
    pub bits_allocated: u16,
    pub bits_stored: u16,
    pub high_bit: u16,
    /// PixelRepresentation 1: two's complement.
    pub signed: bool,
    /// Float Pixel Data (7FE0,0008) or Double Float Pixel Data (7FE0,0009).
    pub float: bool,
}

impl PixelFormat {
    pub(crate) fn sample_bytes(&self) -> usize {
        usize::from(self.bits_allocated / 8)
    }

    pub(crate) fn frame_samples(&self) -> usize {
        self.rows * self.cols
    }

    /// Bytes of one decoded frame (`rows · cols · BitsAllocated/8`, at most 2^32·4).
    pub(crate) fn frame_bytes(&self) -> usize {
        self.frame_samples() * self.sample_bytes()
    }

    /// The voxel type the stored values keep.
    pub(crate) fn voxel_type(&self) -> VoxelType {
        match (self.float, self.bits_allocated, self.signed) {
            (true, 64, _) => VoxelType::F64,
            (true, _, _) => VoxelType::F32,
            (false, 8, false) => VoxelType::U8,
            (false, 8, true) => VoxelType::I8,
            (false, 16, false) => VoxelType::U16,
            (false, 16, true) => VoxelType::I16,
            (false, _, false) => VoxelType::U32,
            (false, _, true) => VoxelType::I32,
        }
    }
}

/// The largest decoded/encoded size ratio a codec can reach, plus slack: decoding a frame
/// larger than `ratio · compressed bytes + 64 KiB` means the header lies.
pub(crate) fn max_ratio(codec: PixelCodec) -> usize {
    match codec {
        // PackBits repeats a byte at most 128 times for 2 bytes.
        PixelCodec::Rle => 64,
        // Huffman codes take at least one bit per sample (lossless) or per 8×8 block
        // (DC + end of block in baseline); the bound is generous.
        PixelCodec::Jpeg => 1024,
        // Deflate's limit is 1032:1.
        PixelCodec::DeflatedFrames => 1032,
        // Empty code blocks make JPEG 2000 of a constant image tiny (a constant 512×512
        // 16-bit frame takes a few hundred bytes); the decoder needs 4 bytes per sample.
        PixelCodec::Jpeg2000 => 2048,
        PixelCodec::Native { .. } | PixelCodec::EncapsulatedNative | PixelCodec::Unsupported => 1,
    }
}

fn decode_error(path: &Path, encoding: &'static str, frame: usize, reason: &str) -> FormatError {
    FormatError::Decode {
        path: path.to_path_buf(),
        encoding,
        offset: 0,
        reason: format!("frame {frame}: {reason}"),
    }
}

/// The fragments of each of `frames` frames (ranges of the data set bytes): by the basic
/// offset table when it has one entry per frame, one fragment per frame, all fragments for a
/// single frame, or else grouped at each fragment that starts a JPEG/JPEG 2000 codestream.
pub(crate) fn frame_fragments(
    path: &Path,
    data: &[u8],
    offset_table: &[u32],
    fragments: &[Range<usize>],
    frames: usize,
) -> Result<Vec<Vec<Range<usize>>>, FormatError> {
    let bad = |reason: String| FormatError::DicomFile {
        path: path.to_path_buf(),
        reason: format!("encapsulated pixel data: {reason}"),
    };
    if fragments.is_empty() {
        return Err(bad("no fragments".into()));
    }
    if frames == 1 {
        return Ok(vec![fragments.to_vec()]);
    }
    if offset_table.len() == frames {
        // Offsets count from the first fragment's item header (8 bytes per item header).
        let mut starts = Vec::with_capacity(fragments.len());
        let mut at = 0u64;
        for f in fragments {
            starts.push(at);
            at += 8 + (f.end - f.start) as u64;
        }
        let mut out = Vec::with_capacity(frames);
        for (i, &o) in offset_table.iter().enumerate() {
            let end = offset_table.get(i + 1).map_or(u64::MAX, |&e| u64::from(e));
            if i > 0 && u64::from(o) <= u64::from(offset_table[i - 1]) {
                return Err(bad(format!(
                    "basic offset table entry {i} ({o}) does not increase"
                )));
            }
            let group: Vec<Range<usize>> = fragments
                .iter()
                .zip(&starts)
                .filter(|&(_, &s)| s >= u64::from(o) && s < end)
                .map(|(f, _)| f.clone())
                .collect();
            if group.is_empty() || !starts.contains(&u64::from(o)) {
                return Err(bad(format!(
                    "basic offset table entry {i} ({o}) is not the start of a fragment"
                )));
            }
            out.push(group);
        }
        return Ok(out);
    }
    if fragments.len() == frames {
        return Ok(fragments.iter().map(|f| vec![f.clone()]).collect());
    }
    // Group at codestream starts: JPEG SOI (FF D8) or JPEG 2000 SOC (FF 4F).
    let mut out: Vec<Vec<Range<usize>>> = Vec::new();
    for f in fragments {
        let head = &data[f.clone()];
        let starts_codestream =
            head.len() >= 2 && head[0] == 0xFF && matches!(head[1], 0xD8 | 0x4F);
        match out.last_mut() {
            Some(group) if !starts_codestream => group.push(f.clone()),
            _ => out.push(vec![f.clone()]),
        }
    }
    if out.len() != frames {
        return Err(bad(format!(
            "{} fragments for {frames} frames, no usable offset table, and {} codestream starts",
            fragments.len(),
            out.len()
        )));
    }
    Ok(out)
}

/// Concatenated bytes of a frame's fragments (borrowed when there is one).
fn joined<'a>(data: &'a [u8], group: &[Range<usize>]) -> Cow<'a, [u8]> {
    match group {
        [one] => Cow::Borrowed(&data[one.clone()]),
        _ => Cow::Owned(
            group
                .iter()
                .flat_map(|r| data[r.clone()].iter().copied())
                .collect(),
        ),
    }
}

/// Decodes every frame of `file` (whose data set bytes were kept) to little-endian samples
/// and hands each to `sink(frame, samples)`.
pub(crate) fn for_each_frame(
    file: &DicomFile,
    format: &PixelFormat,
    frames: usize,
    mut sink: impl FnMut(usize, &[u8]) -> Result<(), FormatError>,
) -> Result<(), FormatError> {
    let path = file.path.as_path();
    let pixel = file.pixel.as_ref().ok_or_else(|| FormatError::DicomFile {
        path: path.to_path_buf(),
        reason: "no pixel data".into(),
    })?;
    let frame_bytes = format.frame_bytes();
    let codec = file.syntax.codec;
    match (&pixel.value, codec) {
        (_, PixelCodec::Unsupported) => Err(FormatError::Unsupported {
            path: path.to_path_buf(),
            field: "TransferSyntaxUID".into(),
            reason: format!(
                "pixel data in transfer syntax {} cannot be decoded (supported: implicit and \
                 explicit VR little endian, explicit VR big endian, deflated, RLE lossless, \
                 JPEG baseline/extended 8-bit/lossless, JPEG 2000)",
                file.syntax.describe()
            ),
        }),
        (PixelValue::Native(range), PixelCodec::Native { big_endian }) => {
            let needed = (frames as u64).saturating_mul(frame_bytes as u64);
            let have = (range.end - range.start) as u64;
            if have < needed {
                return Err(FormatError::TooShort {
                    path: path.to_path_buf(),
                    offset: range.start as u64,
                    needed,
                    available: have,
                });
            }
            let mut swapped = Vec::new();
            for f in 0..frames {
                let start = range.start + f * frame_bytes;
                let bytes = &file.data[start..start + frame_bytes];
                if big_endian && format.sample_bytes() > 1 {
                    swapped.clear();
                    swapped.extend_from_slice(bytes);
                    for s in swapped.chunks_exact_mut(format.sample_bytes()) {
                        s.reverse();
                    }
                    sink(f, &swapped)?;
                } else {
                    sink(f, bytes)?;
                }
            }
            Ok(())
        }
        (
            PixelValue::Encapsulated {
                offset_table,
                fragments,
            },
            _,
        ) if !matches!(codec, PixelCodec::Native { .. }) => {
            let groups = frame_fragments(path, &file.data, offset_table, fragments, frames)?;
            let mut out = Vec::new();
            for (f, group) in groups.iter().enumerate() {
                let encoded = joined(&file.data, group);
                let limit = encoded.len().saturating_mul(max_ratio(codec)) + (64 << 10);
                if frame_bytes > limit {
                    return Err(FormatError::DicomFile {
                        path: path.to_path_buf(),
                        reason: format!(
                            "frame {f}: {} encoded bytes cannot hold {}×{} samples of {} bits \
                             ({frame_bytes} bytes) in {}",
                            encoded.len(),
                            format.cols,
                            format.rows,
                            format.bits_allocated,
                            file.syntax.describe()
                        ),
                    });
                }
                out.clear();
                decode_frame(path, codec, format, f, &encoded, &mut out)?;
                if out.len() != frame_bytes {
                    return Err(decode_error(
                        path,
                        codec_name(codec),
                        f,
                        &format!("decoded {} bytes, expected {frame_bytes}", out.len()),
                    ));
                }
                sink(f, &out)?;
            }
            Ok(())
        }
        (PixelValue::Native(_), _) => Err(FormatError::DicomFile {
            path: path.to_path_buf(),
            reason: format!(
                "transfer syntax {} needs encapsulated pixel data, but it is native",
                file.syntax.describe()
            ),
        }),
        (PixelValue::Encapsulated { .. }, _) => Err(FormatError::DicomFile {
            path: path.to_path_buf(),
            reason: format!(
                "transfer syntax {} needs native pixel data, but it is encapsulated",
                file.syntax.describe()
            ),
        }),
    }
}

fn codec_name(codec: PixelCodec) -> &'static str {
    match codec {
        PixelCodec::Rle => "RLE",
        PixelCodec::Jpeg => "JPEG",
        PixelCodec::Jpeg2000 => "JPEG 2000",
        PixelCodec::DeflatedFrames => "deflate",
        _ => "pixel data",
    }
}

/// Decodes one encapsulated frame into `out` (little-endian samples).
fn decode_frame(
    path: &Path,
    codec: PixelCodec,
    format: &PixelFormat,
    frame: usize,
    encoded: &[u8],
    out: &mut Vec<u8>,
) -> Result<(), FormatError> {
    let name = codec_name(codec);
    let fail = |reason: String| decode_error(path, name, frame, &reason);
    match codec {
        PixelCodec::EncapsulatedNative => {
            let n = format.frame_bytes().min(encoded.len());
            out.extend_from_slice(&encoded[..n]);
            Ok(())
        }
        PixelCodec::DeflatedFrames => {
            flate2::read::DeflateDecoder::new(encoded)
                .take(format.frame_bytes() as u64)
                .read_to_end(out)
                .map_err(|e| fail(e.to_string()))?;
            Ok(())
        }
        PixelCodec::Rle => decode_rle(format, encoded, out).map_err(fail),
        PixelCodec::Jpeg => decode_jpeg(format, encoded, out).map_err(fail),
        PixelCodec::Jpeg2000 => decode_jpeg2000(format, encoded, out).map_err(fail),
        PixelCodec::Native { .. } | PixelCodec::Unsupported => {
            Err(fail("not an encapsulated codec".into()))
        }
    }
}

/// RLE Lossless (PS3.5 Annex G): a 64-byte header of segment count and offsets, then one
/// PackBits segment per byte of each sample, most significant byte first.
fn decode_rle(format: &PixelFormat, encoded: &[u8], out: &mut Vec<u8>) -> Result<(), String> {
    if encoded.len() < 64 {
        return Err(format!(
            "{} bytes, shorter than the 64-byte RLE header",
            encoded.len()
        ));
    }
    let word = |i: usize| {
        u32::from_le_bytes([
            encoded[4 * i],
            encoded[4 * i + 1],
            encoded[4 * i + 2],
            encoded[4 * i + 3],
        ]) as usize
    };
    let count = word(0);
    let bytes = format.sample_bytes();
    if count != bytes {
        return Err(format!(
            "{count} RLE segments, expected {bytes} (one per byte of a {}-bit sample)",
            format.bits_allocated
        ));
    }
    let n = format.frame_samples();
    out.resize(n * bytes, 0);
    let mut plane = Vec::with_capacity(n);
    for s in 0..count {
        let start = word(1 + s);
        let end = if s + 1 < count {
            word(2 + s)
        } else {
            encoded.len()
        };
        if !(64..=encoded.len()).contains(&start) || end < start || end > encoded.len() {
            return Err(format!(
                "RLE segment {s} offsets {start}..{end} lie outside the {} bytes",
                encoded.len()
            ));
        }
        plane.clear();
        unpack_bits(&encoded[start..end], n, &mut plane)
            .map_err(|e| format!("RLE segment {s}: {e}"))?;
        // Segment 0 holds the most significant bytes.
        let byte = bytes - 1 - s;
        for (i, &b) in plane.iter().enumerate() {
            out[i * bytes + byte] = b;
        }
    }
    Ok(())
}

/// PackBits into `out` until `n` bytes (a run past `n` is cut, as encoders pad rows).
fn unpack_bits(src: &[u8], n: usize, out: &mut Vec<u8>) -> Result<(), String> {
    let mut p = 0;
    while out.len() < n {
        let Some(&h) = src.get(p) else {
            return Err(format!("ends after {} of {n} bytes", out.len()));
        };
        p += 1;
        let h = h as i8;
        if h >= 0 {
            let len = h as usize + 1;
            let run = src
                .get(p..p + len)
                .ok_or_else(|| format!("literal run of {len} bytes past the end"))?;
            let take = len.min(n - out.len());
            out.extend_from_slice(&run[..take]);
            p += len;
        } else if h != -128 {
            let len = (1 - isize::from(h)) as usize;
            let &b = src.get(p).ok_or("repeat run past the end")?;
            p += 1;
            let take = len.min(n - out.len());
            out.resize(out.len() + take, b);
        }
    }
    Ok(())
}

/// JPEG (baseline, extended 8-bit, lossless) through `jpeg-decoder`.
fn decode_jpeg(format: &PixelFormat, encoded: &[u8], out: &mut Vec<u8>) -> Result<(), String> {
    use jpeg_decoder::{Decoder, PixelFormat as Jpf};
    let mut decoder = Decoder::new(encoded);
    decoder.set_max_decoding_buffer_size(format.frame_samples() * 2 + 1024);
    decoder.read_info().map_err(|e| e.to_string())?;
    let info = decoder.info().ok_or("no JPEG frame header")?;
    if (usize::from(info.width), usize::from(info.height)) != (format.cols, format.rows) {
        return Err(format!(
            "the JPEG image is {}×{}, the DICOM attributes say {}×{} (Columns×Rows)",
            info.width, info.height, format.cols, format.rows
        ));
    }
    let sample_bytes = match info.pixel_format {
        Jpf::L8 => 1,
        Jpf::L16 => 2,
        other => {
            return Err(format!(
                "the JPEG image is {other:?}; only grayscale (one component) is read"
            ));
        }
    };
    if sample_bytes > format.sample_bytes() {
        return Err(format!(
            "the JPEG samples have more than {} bits (BitsAllocated)",
            format.bits_allocated
        ));
    }
    let pixels = decoder.decode().map_err(|e| e.to_string())?;
    if pixels.len() != format.frame_samples() * sample_bytes {
        return Err(format!(
            "decoded {} bytes for {} samples",
            pixels.len(),
            format.frame_samples()
        ));
    }
    widen(&pixels, sample_bytes, true, format.sample_bytes(), out);
    Ok(())
}

/// Writes samples of `from` bytes (native order when `native`, else little endian) as
/// little-endian samples of `to` bytes (zero-extended; [`store`] sign-extends from BitsStored).
fn widen(src: &[u8], from: usize, native: bool, to: usize, out: &mut Vec<u8>) {
    out.reserve(src.len() / from * to);
    for s in src.chunks_exact(from) {
        let v: u32 = match from {
            1 => u32::from(s[0]),
            2 if native => u32::from(u16::from_ne_bytes([s[0], s[1]])),
            2 => u32::from(u16::from_le_bytes([s[0], s[1]])),
            _ => u32::from_le_bytes([s[0], s[1], s[2], s[3]]),
        };
        out.extend_from_slice(&v.to_le_bytes()[..to]);
    }
}

/// The sign flag and precision of the first component in a JPEG 2000 codestream's SIZ
/// marker (hayro-jpeg2000 decodes every component as unsigned, level-shifted).
fn j2k_component_sign(codestream: &[u8]) -> Option<(bool, u32)> {
    // SIZ follows SOC (FF4F): FF51, Lsiz, Rsiz, 8 × u32 sizes, Csiz, then Ssiz per component.
    let siz = codestream.windows(2).position(|w| w == [0xFF, 0x51])?;
    let ssiz = *codestream.get(siz + 2 + 2 + 2 + 32 + 2)?;
    Some((ssiz & 0x80 != 0, u32::from(ssiz & 0x7F) + 1))
}

/// JPEG 2000 through `hayro-jpeg2000` (codestream or JP2 box).
fn decode_jpeg2000(format: &PixelFormat, encoded: &[u8], out: &mut Vec<u8>) -> Result<(), String> {
    use hayro_jpeg2000::{DecodeSettings, DecoderContext, Image};
    let settings = DecodeSettings {
        resolve_palette_indices: false,
        strict: false,
        target_resolution: None,
    };
    let image = Image::new(encoded, &settings).map_err(|e| format!("{e:?}"))?;
    if (image.width() as usize, image.height() as usize) != (format.cols, format.rows) {
        return Err(format!(
            "the JPEG 2000 image is {}×{}, the DICOM attributes say {}×{} (Columns×Rows)",
            image.width(),
            image.height(),
            format.cols,
            format.rows
        ));
    }
    let precision = u32::from(image.original_bit_depth());
    if precision > u32::from(format.bits_allocated) || format.float {
        return Err(format!(
            "{precision}-bit JPEG 2000 samples do not fit BitsAllocated {}",
            format.bits_allocated
        ));
    }
    let (signed, _) = j2k_component_sign(encoded).unwrap_or((false, precision));
    let mut ctx = DecoderContext::default();
    let decoded = image.decode(&mut ctx).map_err(|e| format!("{e:?}"))?;
    let components = decoded.components();
    if components.len() != 1 {
        return Err(format!(
            "the JPEG 2000 image has {} components; only grayscale (one) is read",
            components.len()
        ));
    }
    let samples = components[0].samples();
    if samples.len() < format.frame_samples() {
        return Err(format!(
            "decoded {} samples, expected {}",
            samples.len(),
            format.frame_samples()
        ));
    }
    let offset = if signed { 1i64 << (precision - 1) } else { 0 };
    let bytes = format.sample_bytes();
    out.reserve(format.frame_bytes());
    for &s in &samples[..format.frame_samples()] {
        // Level-shifted unsigned value back to the stored value (two's complement bits).
        let v = (f64::from(s).round() as i64 - offset) as u64;
        out.extend_from_slice(&v.to_le_bytes()[..bytes]);
    }
    Ok(())
}

/// Where a sample's stored bits lie (BitsStored bits ending at HighBit) and whether they are
/// signed: the one reading of a stored value, decided once per frame.
#[derive(Debug, Clone, Copy)]
struct StoredBits {
    /// Left shift that puts the stored bits at the top of a `u64`.
    up: u32,
    /// Right shift that brings them back down (arithmetic when signed: sign extension).
    down: u32,
    signed: bool,
}

impl StoredBits {
    fn of(format: &PixelFormat) -> Self {
        let bits = u32::from(format.bits_stored);
        let shift = u32::from(format.high_bit + 1 - format.bits_stored);
        Self {
            up: 64 - bits - shift,
            down: 64 - bits,
            signed: format.signed,
        }
    }

    /// The stored value of a little-endian sample word `w` (bits above HighBit, such as
    /// overlays, are dropped).
    #[inline(always)]
    fn value(self, w: u64) -> i64 {
        let top = w << self.up;
        if self.signed {
            (top as i64) >> self.down
        } else {
            (top >> self.down) as i64
        }
    }
}

/// Writes the samples of one frame (little endian, as decoded) into `dst`: stored values, or
/// `slope · stored + intercept` when `rescale` is given.
pub(crate) fn store<T: Voxel>(
    samples: &[u8],
    format: &PixelFormat,
    rescale: Option<(f64, f64)>,
    dst: &mut [T],
) {
    let b = format.sample_bytes();
    if format.float {
        let map = |v: f64| match rescale {
            Some((slope, intercept)) => v * slope + intercept,
            None => v,
        };
        for (d, s) in dst.iter_mut().zip(samples.chunks_exact(b)) {
            let v = if b == 8 {
                f64::from_le_bytes([s[0], s[1], s[2], s[3], s[4], s[5], s[6], s[7]])
            } else {
                f64::from(f32::from_le_bytes([s[0], s[1], s[2], s[3]]))
            };
            *d = T::from_f64(map(v));
        }
        return;
    }
    // Integers: the sample width is dispatched once per frame, not per sample (a CT frame
    // is 2^18 samples; a per-sample copy into a u64 cost more than reading the file).
    match b {
        1 => store_ints(samples.iter().map(|&x| u64::from(x)), format, rescale, dst),
        2 => store_ints(
            samples
                .chunks_exact(2)
                .map(|s| u64::from(u16::from_le_bytes([s[0], s[1]]))),
            format,
            rescale,
            dst,
        ),
        4 => store_ints(
            samples
                .chunks_exact(4)
                .map(|s| u64::from(u32::from_le_bytes([s[0], s[1], s[2], s[3]]))),
            format,
            rescale,
            dst,
        ),
        _ => store_ints(
            samples.chunks_exact(b).map(|s| {
                let mut raw = [0u8; 8];
                raw[..s.len()].copy_from_slice(s);
                u64::from_le_bytes(raw)
            }),
            format,
            rescale,
            dst,
        ),
    }
}

/// [`store`] for integer samples given as raw little-endian words: masked to BitsStored,
/// sign-extended when signed ([`StoredBits`]).
#[inline(always)]
fn store_ints<T: Voxel>(
    raw: impl Iterator<Item = u64>,
    format: &PixelFormat,
    rescale: Option<(f64, f64)>,
    dst: &mut [T],
) {
    let stored = StoredBits::of(format);
    match rescale {
        None => {
            for (d, w) in dst.iter_mut().zip(raw) {
                *d = T::from_f64(stored.value(w) as f64);
            }
        }
        Some((slope, intercept)) => {
            for (d, w) in dst.iter_mut().zip(raw) {
                *d = T::from_f64(stored.value(w) as f64 * slope + intercept);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fmt(bits_allocated: u16, bits_stored: u16, signed: bool) -> PixelFormat {
        PixelFormat {
            rows: 2,
            cols: 2,
            bits_allocated,
            bits_stored,
            high_bit: bits_stored - 1,
            signed,
            float: false,
        }
    }

    #[test]
    fn stored_values_are_masked_and_sign_extended() {
        // 12 bits stored in 16, with overlay bits set above bit 11.
        let f = fmt(16, 12, true);
        let s = 0xF800u16 | 0x0FFF; // -1 in 12 bits, garbage above
        let bits = StoredBits::of(&f);
        assert_eq!(bits.value(u64::from(s)), -1);
        assert_eq!(bits.value(0x07FF), 2047);
        let u = fmt(16, 12, false);
        assert_eq!(StoredBits::of(&u).value(0xFFFF), 4095);
        // HighBit below the top: 12 bits stored at bits 2..=13 of 16.
        let mut shifted = fmt(16, 12, true);
        shifted.high_bit = 13;
        assert_eq!(StoredBits::of(&shifted).value(0xFFFF << 2 | 0b11), -1);
        assert_eq!(StoredBits::of(&shifted).value(0x07FF << 2), 2047);
        // Every width store() dispatches on reads as the generic path does.
        for (ba, bs) in [(8, 8), (16, 16), (32, 32), (32, 20)] {
            for signed in [false, true] {
                let f = fmt(ba, bs, signed);
                let words: Vec<u64> = vec![
                    0,
                    1,
                    (1u64 << (bs - 1)) - 1,
                    1u64 << (bs - 1),
                    (1u64 << bs) - 1,
                ];
                let bytes: Vec<u8> = words
                    .iter()
                    .flat_map(|w| w.to_le_bytes()[..usize::from(ba / 8)].to_vec())
                    .collect();
                let mut got = vec![0f64; words.len()];
                store(&bytes, &f, None, &mut got);
                let want: Vec<f64> = words
                    .iter()
                    .map(|&w| {
                        let w = i64::try_from(w).unwrap();
                        if signed && w >= 1 << (bs - 1) {
                            (w - (1 << bs)) as f64
                        } else {
                            w as f64
                        }
                    })
                    .collect();
                assert_eq!(
                    got, want,
                    "{ba} bits allocated, {bs} stored, signed {signed}"
                );
            }
        }
        let mut out = [0i16; 2];
        store(&[0xFF, 0x0F, 0x00, 0x08], &f, None, &mut out);
        assert_eq!(out, [-1, -2048]);
        let mut f32s = [0f32; 2];
        store(&[0xFF, 0x0F, 0x00, 0x08], &f, Some((2.0, 10.0)), &mut f32s);
        assert_eq!(f32s, [8.0, -4086.0]);
    }

    /// PackBits encoding of one segment (literal runs only, or a repeat run).
    fn rle_frame(segments: &[Vec<u8>]) -> Vec<u8> {
        let mut header = vec![0u8; 64];
        header[..4].copy_from_slice(&(segments.len() as u32).to_le_bytes());
        let mut body: Vec<u8> = Vec::new();
        for (i, s) in segments.iter().enumerate() {
            let at = 64 + body.len() as u32;
            header[4 + 4 * i..8 + 4 * i].copy_from_slice(&at.to_le_bytes());
            body.extend(s);
        }
        header.extend(body);
        header
    }

    #[test]
    fn rle_decodes_msb_first_and_refuses_short_segments() {
        let f = fmt(16, 16, false);
        // Samples 0x0102, 0x0304, 0x0506, 0x0708: MSB segment literal, LSB segment literal.
        let msb = vec![3, 1, 3, 5, 7];
        let lsb = vec![3, 2, 4, 6, 8];
        let mut out = Vec::new();
        decode_rle(&f, &rle_frame(&[msb, lsb.clone()]), &mut out).unwrap();
        assert_eq!(out, vec![2, 1, 4, 3, 6, 5, 8, 7]);
        // A repeat run: -3 → 4 copies of 9.
        let mut out = Vec::new();
        decode_rle(&f, &rle_frame(&[vec![0xFD, 9], lsb]), &mut out).unwrap();
        assert_eq!(out, vec![2, 9, 4, 9, 6, 9, 8, 9]);
        // A segment that ends early: an error, not a panic.
        let mut out = Vec::new();
        let e = decode_rle(
            &f,
            &rle_frame(&[vec![1, 1, 3], vec![3, 2, 4, 6, 8]]),
            &mut out,
        )
        .unwrap_err();
        assert!(
            e.contains("segment 0") && e.contains("ends after 2 of 4"),
            "{e}"
        );
        let e = decode_rle(&f, &[0u8; 10], &mut Vec::new()).unwrap_err();
        assert!(e.contains("64-byte"), "{e}");
        let mut bad = rle_frame(&[vec![0, 1], vec![0, 2]]);
        bad[8..12].copy_from_slice(&9999u32.to_le_bytes());
        assert!(decode_rle(&f, &bad, &mut Vec::new()).is_err());
    }

    #[test]
    fn fragments_group_by_offset_table_or_codestream_start() {
        let data = [0xFF, 0xD8, 1, 2, 3, 4, 0xFF, 0xD8, 5, 6];
        let frags = [0..2, 2..6, 6..10];
        let p = Path::new("x.dcm");
        // Offset table: frame 0 at 0, frame 1 at (8+2)+(8+4) = 22.
        let g = frame_fragments(p, &data, &[0, 22], &frags, 2).unwrap();
        assert_eq!(g, vec![vec![0..2, 2..6], vec![6..10]]);
        // No table: grouped at SOI markers.
        let g = frame_fragments(p, &data, &[], &frags, 2).unwrap();
        assert_eq!(g, vec![vec![0..2, 2..6], vec![6..10]]);
        assert!(frame_fragments(p, &data, &[0, 5], &frags, 2).is_err());
        assert!(frame_fragments(p, &data, &[], &frags, 5).is_err());
    }
}
