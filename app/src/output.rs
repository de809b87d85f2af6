//! Writing the app's outputs (PNG and JPEG images, `.npy` depth maps, JSON and Markdown reports,
//! sessions) through [`formats::output`], so every command and the viewer share one rule:
//! never over an input, an existing file only with `--force` (or a save dialog that asked),
//! a temporary file renamed when complete, every failed write an error.
//!
//! Images are encoded in memory first: the `image` crate's file writer drops its buffer
//! unflushed on error, which loses the last write error (a truncated PNG that "succeeded").

use std::path::Path;

use anyhow::Context as _;
use formats::output::{Replace, write_output};

/// Encodes 8-bit pixels (`Rgba8` or `Rgb8`, row 0 at the top) as a PNG.
pub fn png_bytes(
    pixels: &[u8],
    width: u32,
    height: u32,
    color: image::ExtendedColorType,
) -> anyhow::Result<Vec<u8>> {
    use image::ImageEncoder as _;
    let mut bytes = Vec::new();
    image::codecs::png::PngEncoder::new(&mut bytes)
        .write_image(pixels, width, height, color)
        .context("encoding the PNG")?;
    Ok(bytes)
}

/// The image file types written, chosen by the output's extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImageFormat {
    Png,
    /// Baseline JPEG, quality [`JPEG_QUALITY`], alpha composited over black.
    Jpeg,
}

/// JPEG quality of screenshots and renders: high, since isosurface edges ring at lower ones.
pub const JPEG_QUALITY: u8 = 95;

impl ImageFormat {
    /// The format `path`'s extension names (case-insensitive); any other extension is an
    /// error, so that a `.bmp` never holds PNG bytes.
    pub fn for_path(path: &Path) -> anyhow::Result<Self> {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase());
        match ext.as_deref() {
            Some("png") => Ok(Self::Png),
            Some("jpg" | "jpeg") => Ok(Self::Jpeg),
            _ => anyhow::bail!(
                "{}: images are written as PNG (.png) or JPEG (.jpg, .jpeg); name the output \
                 with one of these extensions",
                path.display()
            ),
        }
    }
}

/// Encodes RGBA8 pixels (row 0 at the top) in `format`.
pub fn rgba_image_bytes(
    rgba8: &[u8],
    width: u32,
    height: u32,
    format: ImageFormat,
) -> anyhow::Result<Vec<u8>> {
    match format {
        ImageFormat::Png => png_bytes(rgba8, width, height, image::ExtendedColorType::Rgba8),
        ImageFormat::Jpeg => {
            use image::ImageEncoder as _;
            // JPEG has no alpha: composite over black, as a viewer shows a transparent pixel.
            let rgb: Vec<u8> = rgba8
                .chunks_exact(4)
                .flat_map(|p| {
                    let a = u16::from(p[3]);
                    [0, 1, 2].map(|c| ((u16::from(p[c]) * a + 127) / 255) as u8)
                })
                .collect();
            let mut bytes = Vec::new();
            image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, JPEG_QUALITY)
                .write_image(&rgb, width, height, image::ExtendedColorType::Rgb8)
                .context("encoding the JPEG")?;
            Ok(bytes)
        }
    }
}

/// Writes RGBA8 pixels as a PNG or JPEG file, by `path`'s extension ([`ImageFormat`]).
pub fn save_rgba_image(
    path: &Path,
    rgba8: &[u8],
    width: u32,
    height: u32,
    replace: Replace,
) -> anyhow::Result<()> {
    // An input or an existing file is the first thing to say, as for every output.
    formats::output::check_output(path, replace)?;
    let format = ImageFormat::for_path(path)?;
    let bytes = rgba_image_bytes(rgba8, width, height, format)
        .with_context(|| path.display().to_string())?;
    write_output(path, &bytes, replace)?;
    Ok(())
}

/// Writes text (JSON, Markdown) as a file.
pub fn save_text(path: &Path, text: &str, replace: Replace) -> anyhow::Result<()> {
    write_output(path, text.as_bytes(), replace)?;
    Ok(())
}
