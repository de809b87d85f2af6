//! Writing the app's outputs (PNG images, `.npy` depth maps, JSON and Markdown reports,
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

/// Writes RGBA8 pixels as a PNG file.
pub fn save_rgba_png(
    path: &Path,
    rgba8: &[u8],
    width: u32,
    height: u32,
    replace: Replace,
) -> anyhow::Result<()> {
    let bytes = png_bytes(rgba8, width, height, image::ExtendedColorType::Rgba8)
        .with_context(|| path.display().to_string())?;
    write_output(path, &bytes, replace)?;
    Ok(())
}

/// Writes text (JSON, Markdown) as a file.
pub fn save_text(path: &Path, text: &str, replace: Replace) -> anyhow::Result<()> {
    write_output(path, text.as_bytes(), replace)?;
    Ok(())
}
