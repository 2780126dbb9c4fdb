//! Making the variants' texels: the rotation and scale of each variant, its size cropped inside
//! the rotated sample, pyramids of texel images, and the bilinear resampling that turns the
//! sample's `(dx, dy)` into the variant's axes.

use super::params::TexelVariantParams;
use crate::geom::geometry_image::TexelImage;
use crate::image::{Image, pyramid};
use rayon::prelude::*;
use texsyn_core::math::PureMath;

/// `cos θ` and `sin θ` of orientation `k` of `count`, exact at multiples of 90°.
pub fn orientation_cos_sin(k: u32, count: u32) -> (f64, f64) {
    let theta = std::f64::consts::TAU * k as f64 / count as f64;
    let snap = |v: f64| {
        if v.abs() < 1e-12 {
            0.0
        } else if (v.abs() - 1.0).abs() < 1e-12 {
            v.signum()
        } else {
            v
        }
    };
    (snap(theta.cos_pure()), snap(theta.sin_pure()))
}

/// Rotates `(dx, dy)` by the angle with cosine `c` and sine `s` (`x' = c x − s y`).
#[inline]
pub(super) fn rotate(c: f64, s: f64, dx: f32, dy: f32) -> (f32, f32) {
    let (dx, dy) = (dx as f64, dy as f64);
    ((c * dx - s * dy) as f32, (s * dx + c * dy) as f32)
}

/// How a variant is resampled: from which level of the sample's pyramid, at what
/// magnification relative to it, and the side of the resulting square.
#[derive(Clone, Copy, Debug)]
pub(super) struct Resampling {
    pub(super) source_level: usize,
    pub(super) magnification: f64,
    pub(super) side: u32,
}

pub(super) fn resampling(
    sample_w: u32,
    sample_h: u32,
    params: &TexelVariantParams,
    scale: usize,
    orientation: u32,
) -> Resampling {
    // Scale factor 2^(middle − scale): 2 for T1, 1 for T2, 1/2 for T3.
    let e = params.middle_scale() as i32 - scale as i32;
    let (source_level, magnification) = if e >= 0 {
        (0usize, (1u32 << e) as f64)
    } else {
        ((-e) as usize, 1.0)
    };
    let (mut w, mut h) = (sample_w, sample_h);
    for _ in 0..source_level {
        w = w.div_ceil(2);
        h = h.div_ceil(2);
    }
    let (c, s) = orientation_cos_sin(orientation, params.orientations);
    let extent = (w.min(h).max(1) - 1) as f64;
    let side = (magnification * extent / (c.abs() + s.abs()) + 1e-6).floor() as u32 + 1;
    Resampling {
        source_level,
        magnification,
        side,
    }
}

/// Sizes of the pyramid levels of a square of side `side`.
pub(super) fn level_sides(side: u32, levels: u32) -> Vec<u32> {
    let mut out = vec![side];
    for _ in 1..levels {
        let last = *out.last().unwrap();
        out.push(last.div_ceil(2));
    }
    out
}

/// Packs a texel image's channels into RGBA images (3 channels each, alpha 1), so the image
/// pyramid code can filter them.
pub(super) fn to_images(t: &TexelImage) -> Vec<Image> {
    let c = t.channels as usize;
    (0..c.div_ceil(3))
        .map(|g| {
            let pixels = t
                .data
                .chunks_exact(c)
                .map(|px| {
                    let mut p = [0.0, 0.0, 0.0, 1.0];
                    for k in 0..3 {
                        if let Some(&v) = px.get(g * 3 + k) {
                            p[k] = v;
                        }
                    }
                    p
                })
                .collect();
            Image {
                width: t.width,
                height: t.height,
                pixels,
            }
        })
        .collect()
}

pub(super) fn from_images(imgs: &[Image], channels: u32) -> TexelImage {
    let (w, h) = (imgs[0].width, imgs[0].height);
    let c = channels as usize;
    let mut out = TexelImage::new(w, h, channels);
    for (i, px) in out.data.chunks_exact_mut(c).enumerate() {
        for (k, v) in px.iter_mut().enumerate() {
            *v = imgs[k / 3].pixels[i][k % 3];
        }
    }
    out
}

/// One Gaussian pyramid step of a texel image: the binomial blur and decimation of
/// [`pyramid::downsample`] on every channel (`w × h` gives `⌈w/2⌉ × ⌈h/2⌉`; texel `i` of the
/// result sits at `2 i`).
pub fn downsample_texels(t: &TexelImage) -> TexelImage {
    let imgs: Vec<Image> = to_images(t)
        .iter()
        .map(|i| pyramid::downsample(i.view()))
        .collect();
    from_images(&imgs, t.channels)
}

/// The Gaussian pyramid of a texel image, `levels` levels (level 0 is the input), however small
/// they get.
pub fn texel_pyramid(t: &TexelImage, levels: usize) -> Vec<TexelImage> {
    let mut out = vec![t.clone()];
    while out.len() < levels {
        let next = downsample_texels(out.last().unwrap());
        out.push(next);
    }
    out
}

/// Bilinear sample of a texel image at a continuous address (integers = texel centres),
/// coordinates clamped to the image.
pub(super) fn bilinear(t: &TexelImage, x: f64, y: f64, out: &mut [f32]) {
    let x = x.clamp(0.0, (t.width - 1) as f64);
    let y = y.clamp(0.0, (t.height - 1) as f64);
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
    let (x0, y0) = (x0 as u32, y0 as u32);
    let x1 = (x0 + 1).min(t.width - 1);
    let y1 = (y0 + 1).min(t.height - 1);
    let (a, b, c, d) = (
        t.texel(x0, y0),
        t.texel(x1, y0),
        t.texel(x0, y1),
        t.texel(x1, y1),
    );
    for k in 0..out.len() {
        let top = a[k] + (b[k] - a[k]) * fx;
        let bot = c[k] + (d[k] - c[k]) * fx;
        out[k] = top + (bot - top) * fy;
    }
}

/// The rotated, scaled and cropped sample of one variant (level 0), see the module docs.
/// `sources` is the sample's pyramid (as many levels as the smallest scale needs).
pub fn resample_variant(
    sources: &[TexelImage],
    params: &TexelVariantParams,
    scale: usize,
    orientation: u32,
) -> TexelImage {
    let s0 = &sources[0];
    let rs = resampling(s0.width, s0.height, params, scale, orientation);
    let src = &sources[rs.source_level];
    let (cos, sin) = orientation_cos_sin(orientation, params.orientations);
    let c = src.channels as usize;
    let side = rs.side;
    let mut out = TexelImage::new(side, side, src.channels);
    let half_v = (side as f64 - 1.0) / 2.0;
    let (cx, cy) = (
        (src.width as f64 - 1.0) / 2.0,
        (src.height as f64 - 1.0) / 2.0,
    );
    let m = rs.magnification;
    out.data
        .par_chunks_mut(side as usize * c)
        .enumerate()
        .for_each(|(py, row)| {
            for (px, o) in row.chunks_exact_mut(c).enumerate() {
                let (ux, uy) = (px as f64 - half_v, py as f64 - half_v);
                // Source point: R(−θ) u / m about the source centre.
                let sx = cx + (cos * ux + sin * uy) / m;
                let sy = cy + (-sin * ux + cos * uy) / m;
                bilinear(src, sx, sy, o);
                let (dx, dy) = rotate(cos, sin, o[0], o[1]);
                o[0] = dx;
                o[1] = dy;
            }
        });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn variant_sizes_crop_inside_the_rotated_sample() {
        let p = TexelVariantParams::default();
        // 0°: the whole sample (scaled); 45°: side / √2.
        assert_eq!(resampling(64, 64, &p, 1, 0).side, 64);
        assert_eq!(resampling(64, 64, &p, 0, 0).side, 127);
        assert_eq!(resampling(64, 64, &p, 2, 0).side, 32);
        assert_eq!(resampling(64, 64, &p, 1, 2).side, 64); // 90°
        assert_eq!(
            resampling(64, 64, &p, 1, 1).side,
            (63.0 / 2f64.sqrt()) as u32 + 1
        );
    }
}
