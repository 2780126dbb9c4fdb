//! Renders an image from per-pixel exemplar addresses, optionally blending across patch seams.
//!
//! The final step of the image jump-map synthesis of S. Zelinka and M. Garland, "Towards
//! real-time texture synthesis with the jump map" (EGWR 2002), reviewed in §4.2.1 of
//! "Interactive texture synthesis on surfaces using jump maps" (2003): "blending may be applied
//! by copying each pixel with a small blend kernel". Each output pixel `p` is the Gaussian-
//! weighted average, over the output pixels `q` within `r` of `p` (a `(2r+1)²` square, clipped
//! to the output), of the exemplar pixel `addr(q) + (p − q)`: what `q`'s patch would put at `p`.
//! Inside a patch all terms agree, so the blend only changes pixels near seams. The Gaussian's
//! standard deviation is `r / 2 + 0.5`. Exemplar reads are clamped to its edges.
//!
//! The addresses are the synthesis result; any exemplar-aligned map (colour, normals, height)
//! can be rendered from the same addresses.

use crate::image::{Image, ImageView};
use rayon::prelude::*;
use texsyn_core::math::PureMath;

/// The `blend_2d` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("blend_2d", 1);

/// The blend radius that looked best on the test exemplars with the default synthesis
/// parameters: 1 (a 3×3 kernel, σ = 1). 0 leaves jagged seams; 2 visibly softens them.
pub const DEFAULT_BLEND_RADIUS: u32 = 1;

/// `[reconstruct]` of `synth2d`.
#[derive(Debug, Clone, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct Blend2dParams {
    /// Radius of the blend kernel, 0..=8 (0 copies pixels). Default: 1.
    pub blend_radius: u32,
}

impl Default for Blend2dParams {
    fn default() -> Self {
        Blend2dParams {
            blend_radius: DEFAULT_BLEND_RADIUS,
        }
    }
}

impl Blend2dParams {
    pub fn validate(&self) -> Result<(), texsyn_core::check::ParamError> {
        texsyn_core::check::check_range("reconstruct.blend_radius", self.blend_radius, 0, 8)
    }
}

/// The reconstruct node: `synthesized.png`, rendered from the addresses, and
/// `coordinates.png`, the addresses themselves (red = x, green = y, scaled to the exemplar),
/// with which a user applies the same synthesis to other maps of the material.
pub fn node(
    exemplar: ImageView,
    addresses: &[[u16; 2]],
    (width, height): (u32, u32),
    p: &Blend2dParams,
) -> Vec<(String, Vec<u8>)> {
    use crate::reconstruct::textured_export::encode_png;
    let img = render_2d(exemplar, addresses, width, height, p.blend_radius);
    let mut coords = Image::new(width, height);
    for (px, a) in coords.pixels.iter_mut().zip(addresses) {
        *px = [
            a[0] as f32 / (exemplar.width.max(2) - 1) as f32,
            a[1] as f32 / (exemplar.height.max(2) - 1) as f32,
            0.0,
            1.0,
        ];
    }
    vec![
        ("synthesized.png".into(), encode_png(&img.to_rgba8(), false)),
        (
            "coordinates.png".into(),
            encode_png(&coords.to_rgba8(), false),
        ),
    ]
}

/// Renders `width × height` pixels from `addresses` (row-major `[x, y]` exemplar addresses).
/// `blend_radius == 0` copies each pixel. All four channels are blended alike.
///
/// Panics if `addresses.len() != width * height`.
pub fn render_2d(
    exemplar: ImageView,
    addresses: &[[u16; 2]],
    width: u32,
    height: u32,
    blend_radius: u32,
) -> Image {
    let (w, h) = (width as usize, height as usize);
    assert_eq!(addresses.len(), w * h, "one address per output pixel");
    let mut out = Image::new(width, height);
    if w == 0 || h == 0 || exemplar.width == 0 || exemplar.height == 0 {
        return out;
    }
    let r = blend_radius as i64;
    let sigma = blend_radius as f32 / 2.0 + 0.5;
    let kernel: Vec<f32> = (-r..=r)
        .map(|d| (-((d * d) as f32) / (2.0 * sigma * sigma)).exp_pure())
        .collect();
    out.pixels
        .par_chunks_mut(w)
        .enumerate()
        .for_each(|(y, row)| {
            let y = y as i64;
            for (x, o) in row.iter_mut().enumerate() {
                let x = x as i64;
                if r == 0 {
                    let a = addresses[y as usize * w + x as usize];
                    *o = exemplar.get_clamped(a[0] as i64, a[1] as i64);
                    continue;
                }
                let mut acc = [0.0f32; 4];
                let mut wsum = 0.0f32;
                for dy in -r..=r {
                    let qy = y + dy;
                    if qy < 0 || qy >= h as i64 {
                        continue;
                    }
                    let wy = kernel[(dy + r) as usize];
                    for dx in -r..=r {
                        let qx = x + dx;
                        if qx < 0 || qx >= w as i64 {
                            continue;
                        }
                        let wgt = wy * kernel[(dx + r) as usize];
                        let a = addresses[qy as usize * w + qx as usize];
                        let c = exemplar.get_clamped(a[0] as i64 - dx, a[1] as i64 - dy);
                        for k in 0..4 {
                            acc[k] += wgt * c[k];
                        }
                        wsum += wgt;
                    }
                }
                for k in 0..4 {
                    o[k] = acc[k] / wsum;
                }
            }
        });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn exemplar() -> Image {
        let mut img = Image::new(8, 8);
        for (i, p) in img.pixels.iter_mut().enumerate() {
            *p = [
                (i % 8) as f32 / 8.0,
                (i / 8) as f32 / 8.0,
                ((i * 7) % 5) as f32 / 5.0,
                1.0,
            ];
        }
        img
    }

    #[test]
    fn radius_zero_copies_and_coherent_patches_are_unchanged_by_blending() {
        let ex = exemplar();
        // A single coherent patch: address = p + (2, 1), kept inside the exemplar.
        let (w, h) = (5u32, 6u32);
        let addr: Vec<[u16; 2]> = (0..w * h)
            .map(|i| [(i % w + 2) as u16, (i / w + 1) as u16])
            .collect();
        let copy = render_2d(ex.view(), &addr, w, h, 0);
        for y in 0..h {
            for x in 0..w {
                assert_eq!(copy.view().get(x, y), ex.view().get(x + 2, y + 1));
            }
        }
        let blended = render_2d(ex.view(), &addr, w, h, 2);
        for (a, b) in blended.pixels.iter().zip(&copy.pixels) {
            for k in 0..4 {
                assert!((a[k] - b[k]).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn seams_are_averaged() {
        // Left half from one place, right half from another: at the seam the blend mixes both
        // patches' continuations, away from it pixels are copies.
        let ex = exemplar();
        let (w, h) = (6u32, 1u32);
        let addr: Vec<[u16; 2]> = (0..6)
            .map(|x| {
                if x < 3 {
                    [x as u16, 0]
                } else {
                    [x as u16 - 3, 5]
                }
            })
            .collect();
        let b = render_2d(ex.view(), &addr, w, h, 1);
        let k = [(-0.5f32).exp_pure(), 1.0, (-0.5f32).exp_pure()]; // sigma = 1
        // Pixel 2: q = 1, 2 from patch A (address x), q = 3 from patch B, whose continuation to
        // p = 2 is (-1, 5), clamped to (0, 5).
        let want = (k[0] * ex.view().get(2, 0)[1]
            + k[1] * ex.view().get(2, 0)[1]
            + k[2] * ex.view().get(0, 5)[1])
            / (k[0] + k[1] + k[2]);
        assert!((b.view().get(2, 0)[1] - want).abs() < 1e-6);
        assert_eq!(b.view().get(0, 0), ex.view().get(0, 0));
    }
}
