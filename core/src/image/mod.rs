//! Exemplar images and what is computed from them: Gaussian pyramids, neighbourhood vectors,
//! PCA, nearest-neighbour search.
//!
//! Pixel addresses: `(x, y)` with `x` to the right and `y` down, integer coordinates at pixel
//! centres, so the valid continuous range of an image `w × h` is `[0, w-1] × [0, h-1]`.
//! Texture coordinates written to files follow OBJ/glTF conventions and are converted in one
//! place ([`texel_to_uv`]).

pub mod knn;
pub mod neighbourhood;
pub mod patch_score;
pub mod pca;
pub mod pyramid;

use glam::Vec2;
use std::path::{Path, PathBuf};

/// An RGBA image with f32 channels in [0, 1] (8-bit inputs are divided by 255 and keep their
/// sRGB encoding: synthesis copies and compares pixels, it never lights them).
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<[f32; 4]>,
}

/// A borrowed image: the owned [`Image`] and a memory-mapped artifact both give one.
#[derive(Debug, Clone, Copy)]
pub struct ImageView<'a> {
    pub width: u32,
    pub height: u32,
    pub pixels: &'a [[f32; 4]],
}

impl Image {
    pub fn new(width: u32, height: u32) -> Self {
        Image {
            width,
            height,
            pixels: vec![[0.0, 0.0, 0.0, 1.0]; width as usize * height as usize],
        }
    }

    /// An image whose pixel `(x, y)` is `f(x, y)`, called row by row, left to right.
    pub fn from_fn(width: u32, height: u32, mut f: impl FnMut(u32, u32) -> [f32; 4]) -> Self {
        let mut pixels = Vec::with_capacity(width as usize * height as usize);
        for y in 0..height {
            for x in 0..width {
                pixels.push(f(x, y));
            }
        }
        Image {
            width,
            height,
            pixels,
        }
    }

    pub fn view(&self) -> ImageView<'_> {
        ImageView {
            width: self.width,
            height: self.height,
            pixels: &self.pixels,
        }
    }

    /// 8-bit sRGB-encoded RGBA, as PNG writers want it.
    pub fn to_rgba8(&self) -> image::RgbaImage {
        self.view().to_rgba8()
    }
}

impl<'a> ImageView<'a> {
    #[inline]
    pub fn get(&self, x: u32, y: u32) -> [f32; 4] {
        self.pixels[(y * self.width + x) as usize]
    }

    /// Pixel with coordinates clamped to the image.
    #[inline]
    pub fn get_clamped(&self, x: i64, y: i64) -> [f32; 4] {
        let x = x.clamp(0, self.width as i64 - 1) as u32;
        let y = y.clamp(0, self.height as i64 - 1) as u32;
        self.get(x, y)
    }

    /// Bilinear sample at a continuous texel address (integer = pixel centre), clamped.
    #[inline]
    pub fn sample(&self, p: Vec2) -> [f32; 4] {
        let x0 = p.x.floor();
        let y0 = p.y.floor();
        let fx = p.x - x0;
        let fy = p.y - y0;
        // `as` saturates a huge or infinite address; the neighbour saturates too.
        let (x0, y0) = (x0 as i64, y0 as i64);
        let (x1, y1) = (x0.saturating_add(1), y0.saturating_add(1));
        let a = self.get_clamped(x0, y0);
        let b = self.get_clamped(x1, y0);
        let c = self.get_clamped(x0, y1);
        let d = self.get_clamped(x1, y1);
        let mut out = [0.0; 4];
        for k in 0..4 {
            let top = a[k] + (b[k] - a[k]) * fx;
            let bot = c[k] + (d[k] - c[k]) * fx;
            out[k] = top + (bot - top) * fy;
        }
        out
    }

    pub fn to_owned(&self) -> Image {
        Image {
            width: self.width,
            height: self.height,
            pixels: self.pixels.to_vec(),
        }
    }

    /// The image mirrored about its main diagonal: pixel (x, y) goes to (y, x).
    pub fn transposed(&self) -> Image {
        let mut out = Image::new(self.height, self.width);
        for y in 0..self.height {
            for x in 0..self.width {
                out.pixels[(x * self.height + y) as usize] =
                    self.pixels[(y * self.width + x) as usize];
            }
        }
        out
    }

    pub fn to_rgba8(&self) -> image::RgbaImage {
        let mut out = image::RgbaImage::new(self.width, self.height);
        for (dst, src) in out.pixels_mut().zip(self.pixels) {
            for k in 0..4 {
                dst.0[k] = (src[k].clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
            }
        }
        out
    }
}

/// Texel address (pixel centres at integers, y down) to OBJ/glTF-style texture coordinates
/// (u right, v up, [0, 1] over the image). glTF's v points down; [`uv_for_gltf`] flips it.
#[inline]
pub fn texel_to_uv(p: Vec2, width: u32, height: u32) -> Vec2 {
    Vec2::new(
        (p.x + 0.5) / width as f32,
        1.0 - (p.y + 0.5) / height as f32,
    )
}

/// OBJ-style uv (v up) to glTF-style uv (v down).
#[inline]
pub fn uv_for_gltf(uv: Vec2) -> Vec2 {
    Vec2::new(uv.x, 1.0 - uv.y)
}

/// An image file that could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: cannot decode image: {message}")]
    Decode { path: PathBuf, message: String },
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
}

/// Decodes a PNG, JPEG or EXR file from bytes already read (the caller hashed them).
pub fn decode_image(path: &Path, bytes: &[u8]) -> Result<Image, ImageError> {
    let is_exr = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
        || bytes.starts_with(&[0x76, 0x2f, 0x31, 0x01]);
    let img = if is_exr {
        decode_exr(path, bytes)?
    } else {
        check_jpeg_complete(path, bytes)?;
        let dynimg = image::load_from_memory(bytes).map_err(|e| ImageError::Decode {
            path: path.to_owned(),
            message: e.to_string(),
        })?;
        let rgba = dynimg.to_rgba32f();
        let (width, height) = rgba.dimensions();
        let pixels = rgba
            .pixels()
            .map(|p| [p.0[0], p.0[1], p.0[2], p.0[3]])
            .collect();
        Image {
            width,
            height,
            pixels,
        }
    };
    if img.width == 0 || img.height == 0 {
        return Err(ImageError::Invalid {
            path: path.to_owned(),
            message: "image is empty (0 pixels)".into(),
        });
    }
    if let Some(i) = img
        .pixels
        .iter()
        .position(|p| p.iter().any(|c| !c.is_finite()))
    {
        return Err(ImageError::Invalid {
            path: path.to_owned(),
            message: format!(
                "pixel ({}, {}) is not a finite number",
                i as u32 % img.width,
                i as u32 / img.width
            ),
        });
    }
    Ok(img)
}

/// Refuses a JPEG cut short: the decoder fills what is missing with grey and says nothing. A
/// whole JPEG has an end-of-image marker (`FF D9`) after its last scan (`FF DA`); inside a
/// scan's entropy-coded data an `FF` byte is always followed by `00` or a restart marker, so
/// neither marker can appear there, and an embedded thumbnail's markers come before the main
/// image's.
fn check_jpeg_complete(path: &Path, bytes: &[u8]) -> Result<(), ImageError> {
    if !bytes.starts_with(&[0xFF, 0xD8, 0xFF]) {
        return Ok(());
    }
    let last = |marker: u8| bytes.windows(2).rposition(|w| w == [0xFF, marker]);
    match (last(0xDA), last(0xD9)) {
        (Some(scan), Some(end)) if end > scan => Ok(()),
        _ => Err(ImageError::Invalid {
            path: path.to_owned(),
            message: format!(
                "JPEG is truncated: no end-of-image marker after its last scan ({} bytes read); \
                 the file was cut short, re-export or copy it again",
                bytes.len()
            ),
        }),
    }
}

fn decode_exr(path: &Path, bytes: &[u8]) -> Result<Image, ImageError> {
    use exr::prelude::{ReadChannels, ReadLayers};
    // The pixels are allocated from the header's size before any are read: a header must not
    // claim more than the file could hold (deflate packs at most about 1032 bytes into one,
    // and a pixel takes at least 2 bytes, so 1024 pixels per byte is beyond any real file).
    let meta = exr::meta::MetaData::read_from_buffered(std::io::Cursor::new(bytes), false)
        .map_err(|e| ImageError::Decode {
            path: path.to_owned(),
            message: e.to_string(),
        })?;
    for h in &meta.headers {
        let pixels = h.layer_size.width().saturating_mul(h.layer_size.height());
        if pixels > bytes.len().saturating_mul(1024) {
            return Err(ImageError::Invalid {
                path: path.to_owned(),
                message: format!(
                    "the header declares {}×{} pixels, more than a file of {} bytes can hold",
                    h.layer_size.width(),
                    h.layer_size.height(),
                    bytes.len()
                ),
            });
        }
    }
    let reader = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .rgba_channels(
            |resolution, _| Image {
                width: resolution.width() as u32,
                height: resolution.height() as u32,
                pixels: vec![[0.0, 0.0, 0.0, 1.0]; resolution.width() * resolution.height()],
            },
            |img: &mut Image, pos: exr::math::Vec2<usize>, (r, g, b, a): (f32, f32, f32, f32)| {
                let i = pos.y() * img.width as usize + pos.x();
                img.pixels[i] = [r, g, b, a];
            },
        )
        .first_valid_layer()
        .all_attributes();
    let decoded = reader
        .from_buffered(std::io::Cursor::new(bytes))
        .map_err(|e| ImageError::Decode {
            path: path.to_owned(),
            message: e.to_string(),
        })?;
    Ok(decoded.layer_data.channel_data.pixels)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_truncated_jpeg_is_refused_and_a_whole_one_read() {
        let img =
            image::RgbImage::from_fn(64, 48, |x, y| image::Rgb([x as u8 * 3, y as u8 * 5, 90]));
        let mut bytes = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, 90)
            .encode_image(&img)
            .unwrap();
        let path = Path::new("e.jpg");
        let whole = decode_image(path, &bytes).unwrap();
        assert_eq!((whole.width, whole.height), (64, 48));
        for keep in [bytes.len() - 2, bytes.len() * 3 / 4, bytes.len() / 2] {
            let e = decode_image(path, &bytes[..keep]).unwrap_err().to_string();
            assert!(
                e.contains("e.jpg") && e.contains("truncated"),
                "{keep}: {e}"
            );
        }
        // Trailing bytes after the end marker (some cameras append data) are accepted.
        let mut padded = bytes.clone();
        padded.extend_from_slice(&[0u8; 16]);
        assert!(decode_image(path, &padded).is_ok());
    }

    #[test]
    fn bilinear_sample_hits_pixel_centres_and_midpoints() {
        let mut img = Image::new(2, 1);
        img.pixels[0] = [0.0, 0.0, 0.0, 1.0];
        img.pixels[1] = [1.0, 0.5, 0.0, 1.0];
        let v = img.view();
        assert_eq!(v.sample(Vec2::new(0.0, 0.0)), [0.0, 0.0, 0.0, 1.0]);
        assert_eq!(v.sample(Vec2::new(1.0, 0.0)), [1.0, 0.5, 0.0, 1.0]);
        assert_eq!(v.sample(Vec2::new(0.5, 0.0)), [0.5, 0.25, 0.0, 1.0]);
        // Clamped outside.
        assert_eq!(v.sample(Vec2::new(5.0, -3.0)), [1.0, 0.5, 0.0, 1.0]);
    }

    #[test]
    fn texel_centres_map_inside_unit_square() {
        let uv = texel_to_uv(Vec2::new(0.0, 0.0), 4, 4);
        assert_eq!(uv, Vec2::new(0.125, 0.875));
        let uv = texel_to_uv(Vec2::new(3.0, 3.0), 4, 4);
        assert_eq!(uv, Vec2::new(0.875, 0.125));
    }

    #[test]
    fn an_exr_header_claiming_more_pixels_than_the_file_holds_is_refused_before_allocating() {
        let mut bytes = crate::export::exr::write_exr_rgb(2, 2, &[glam::Vec3::ONE; 4]).unwrap();
        assert!(decode_image(Path::new("x.exr"), &bytes).is_ok());
        // The data window (box2i: xmin, ymin, xmax, ymax) made 10⁶ × 10⁶ pixels.
        let key = b"dataWindow\0box2i\0";
        let at = bytes.windows(key.len()).position(|w| w == key).unwrap() + key.len() + 4;
        bytes[at + 8..at + 12].copy_from_slice(&999_999i32.to_le_bytes());
        bytes[at + 12..at + 16].copy_from_slice(&999_999i32.to_le_bytes());
        let e = decode_image(Path::new("x.exr"), &bytes).unwrap_err();
        assert!(
            e.to_string().starts_with("x.exr: ") && e.to_string().contains("1000000×1000000"),
            "{e}"
        );
    }

    #[test]
    fn garbage_bytes_are_a_decode_error_naming_the_file() {
        let e = decode_image(Path::new("x.png"), b"not a png").unwrap_err();
        assert!(e.to_string().starts_with("x.png: cannot decode"), "{e}");
    }
}
