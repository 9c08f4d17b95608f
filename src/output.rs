//! Every file the command line writes, written the one safe way
//! ([`spomp_behaviors::mission::output`]): a symbolic or hard link planted in an output folder
//! is refused or replaced, never written through, and whole files appear atomically under
//! their name (a temporary file with an unpredictable name, renamed).

use std::path::Path;

use anyhow::{Context, Result, anyhow};
use image::{EncodableLayout, ImageBuffer, PixelWithColorType};
use plotters::coord::Shift;
use plotters::prelude::{BitMapBackend, DrawingArea, IntoDrawingArea};
use spomp_behaviors::mission::output;

/// Writes `bytes` as the whole of `path` (see [`output::write_file`]).
pub fn write(path: &Path, bytes: impl AsRef<[u8]>) -> Result<()> {
    output::write_file(path, bytes.as_ref()).with_context(|| format!("writing {}", path.display()))
}

/// Creates a folder the command fills (`trial-1`, `plots`): not a symbolic link planted there.
pub fn create_dir(path: &Path) -> Result<()> {
    output::create_dir(path).with_context(|| format!("creating {}", path.display()))
}

/// The PNG encoding of an image.
pub fn png_bytes<P, C>(img: &ImageBuffer<P, C>) -> Result<Vec<u8>>
where
    P: PixelWithColorType,
    [P::Subpixel]: EncodableLayout,
    C: std::ops::Deref<Target = [P::Subpixel]>,
{
    let mut bytes = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut bytes), image::ImageFormat::Png).context("encoding a PNG")?;
    Ok(bytes)
}

/// Writes an image as a PNG file.
pub fn write_png<P, C>(img: &ImageBuffer<P, C>, path: &Path) -> Result<()>
where
    P: PixelWithColorType,
    [P::Subpixel]: EncodableLayout,
    C: std::ops::Deref<Target = [P::Subpixel]>,
{
    write(path, png_bytes(img).with_context(|| format!("writing {}", path.display()))?)
}

/// What a plot's drawing code returns (plotters' errors are of several types).
pub type DrawResult = std::result::Result<(), Box<dyn std::error::Error>>;

/// Draws a `size` plot in memory with `draw`, then writes it as a PNG file at `path`.
pub fn plot_png(
    path: &Path,
    size: (u32, u32),
    draw: impl FnOnce(&DrawingArea<BitMapBackend<'_>, Shift>) -> DrawResult,
) -> Result<()> {
    let mut pixels = vec![0u8; size.0 as usize * size.1 as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut pixels, size).into_drawing_area();
        draw(&root).map_err(|e| anyhow!("drawing {}: {e}", path.display()))?;
        root.present().map_err(|e| anyhow!("drawing {}: {e}", path.display()))?;
    }
    let img = image::RgbImage::from_raw(size.0, size.1, pixels)
        .ok_or_else(|| anyhow!("drawing {}: the pixel buffer does not fit the size", path.display()))?;
    write_png(&img, path)
}
