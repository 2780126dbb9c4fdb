//! Feature masks for regular exemplars (Zhang, Du, Lai, Ni & Hu, "Sketch guided solid
//! texturing", §4 and §6, Fig. 16): "for exemplar image textures with high regularity (e.g.
//! bricks), a further feature component is introduced, using high intensity to indicate
//! feature curves. Such feature curves in the input image may be obtained automatically, or
//! specified by the user".
//!
//! The paper does not say how the component enters matching. Here it follows Lefebvre & Hoppe's
//! appearance-space feature channel ("Appearance-space texture synthesis", 2006, §4.2): a
//! per-pixel channel derived from the feature mask is appended, with a weight, to the pixel's
//! colour, and the augmented per-pixel vectors are reduced by PCA — matching then runs on the
//! reduced *appearance* vectors instead of the colours, while the output keeps the colours.
//!
//! What is done, per distinct exemplar image:
//! 1. Feature lines: drawn by the user (a mask image beside the exemplar, its texels at or
//!    above half intensity on the curves: [`drawn_channel`]), or else detected automatically
//!    with the curvilinear detector of `texture_feature_lines.rs` (the feature-aligned
//!    method's, after Wu & Yu 2004; dark lines by default), on the image tiled 3 × 3 so that
//!    lines and distances wrap around as the solid analysis treats exemplars (toroidal).
//! 2. The channel: `F = 1 − min(d, R) / R`, `d` the distance in texels to the nearest line
//!    texel and `R` = `radius`: 1 on a feature curve ("high intensity"), falling to 0 at `R`
//!    texels — L&H's feature-distance channel, clamped so that the wide insides of regions,
//!    which colour already describes, do not dominate.
//! 3. Appearance: `(r, g, b, weight · F)` reduced to 3 dimensions by PCA (L&H reduce their
//!    appearance vectors by PCA too, to 8 dimensions; 3 here because the synthesis carries
//!    three channels per voxel — the least-variance direction is dropped, and
//!    [`Appearance::kept_variance`] says how much that was).
//!
//! The appearance images then replace the colours in everything that *matches* (the Gaussian
//! stacks' neighbourhood vectors and their PCA, crossbar lines and errors, slab seeds, the
//! synthesized voxels' neighbourhoods), see `candidate_triples.rs`.

use super::texture_feature_lines::{
    Polarity, TextureFeatureParams, detect_texture_features, distance_transform,
};
use crate::image::pca::{Pca, PcaParams};
use crate::image::{Image, ImageView};
use serde::{Deserialize, Serialize};

/// `[analyse_exemplar.feature_mask]` of the solid method; its presence turns the feature
/// channel on.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FeatureMaskParams {
    /// Weight of the feature channel against the colours (in [0, 1]), 0..=100. Default: 1.
    pub weight: f32,
    /// Distance in texels over which the channel falls from 1 (on a line) to 0, 0.5..=256.
    /// Default: 6.
    pub radius: f32,
    /// Which lines are features: "dark" (mortar, gaps; default), "bright" or "both".
    pub polarity: Polarity,
    /// The line detector's σ in texels, 0.5..=16. Default: 1.
    pub scale: f32,
    /// Fraction of the strongest line response that starts a line, 0..=1. Default: 0.5.
    pub threshold: f32,
    /// Shortest line kept, in texels. Default: 8.
    pub min_length: f32,
}

impl Default for FeatureMaskParams {
    fn default() -> Self {
        let d = TextureFeatureParams::default();
        FeatureMaskParams {
            weight: 1.0,
            radius: 6.0,
            polarity: d.polarity,
            scale: d.scale,
            threshold: d.threshold,
            min_length: d.min_length,
        }
    }
}

impl FeatureMaskParams {
    fn detector(&self) -> TextureFeatureParams {
        TextureFeatureParams {
            polarity: self.polarity,
            scale: self.scale,
            threshold: self.threshold,
            min_length: self.min_length,
            direction: None,
        }
    }

    /// The first setting out of range, as (name, value, message).
    pub fn invalid(&self) -> Option<(&'static str, f32, &'static str)> {
        let ok = |x: f32, lo: f32, hi: f32| x.is_finite() && (lo..=hi).contains(&x);
        [
            (
                "feature_mask.weight",
                self.weight,
                0.0,
                100.0,
                "expected 0..=100",
            ),
            (
                "feature_mask.radius",
                self.radius,
                0.5,
                256.0,
                "expected 0.5..=256",
            ),
            (
                "feature_mask.scale",
                self.scale,
                0.5,
                16.0,
                "expected 0.5..=16",
            ),
            (
                "feature_mask.threshold",
                self.threshold,
                0.0,
                1.0,
                "expected 0..=1",
            ),
            (
                "feature_mask.min_length",
                self.min_length,
                0.0,
                65536.0,
                "expected 0..=65536",
            ),
        ]
        .into_iter()
        .find(|(_, x, lo, hi, _)| !ok(*x, *lo, *hi))
        .map(|(name, x, _, _, expected)| (name, x, expected))
    }
}

/// An exemplar in appearance space.
#[derive(Clone, Debug)]
pub struct Appearance {
    /// The feature channel `F` per texel, row-major (1 on a line).
    pub channel: Vec<f32>,
    /// The appearance image: `(r, g, b, weight · F)` projected on its 3 principal axes.
    pub image: Image,
    /// Fraction of the 4-D appearance variance the 3 kept dimensions hold.
    pub kept_variance: f32,
}

/// The feature channel of an exemplar (steps 1–2 of the module docs); an error when the
/// detector finds no line.
pub fn feature_channel(img: ImageView, p: &FeatureMaskParams) -> Result<Vec<f32>, String> {
    let (w, h) = (img.width as usize, img.height as usize);
    // Tiled 3 × 3, so detection and distances wrap around; the centre tile is kept.
    let tiled = Image::from_fn(3 * w as u32, 3 * h as u32, |x, y| {
        img.pixels[(y as usize % h) * w + x as usize % w]
    });
    let f = detect_texture_features(&tiled, &p.detector()).map_err(|e| e.to_string())?;
    let mut on = vec![false; 9 * w * h];
    for line in &f.lines {
        for q in line {
            let (x, y) = (q[0].round() as usize, q[1].round() as usize);
            if x < 3 * w && y < 3 * h {
                on[y * 3 * w + x] = true;
            }
        }
    }
    Ok(falloff(&on, w, h, p.radius))
}

/// The feature channel of a drawn mask (`w × h`, the size of its exemplar): its texels whose
/// mean of red, green and blue is at least ½ are the feature curves; distances wrap around.
/// An error when no texel is.
pub fn drawn_channel(mask: ImageView, p: &FeatureMaskParams) -> Result<Vec<f32>, String> {
    let (w, h) = (mask.width as usize, mask.height as usize);
    let drawn = |x: usize, y: usize| {
        let c = mask.pixels[(y % h) * w + x % w];
        (c[0] + c[1] + c[2]) / 3.0 >= 0.5
    };
    if !(0..h).any(|y| (0..w).any(|x| drawn(x, y))) {
        return Err("the drawn mask has no feature texel (none at or above half intensity)".into());
    }
    let on: Vec<bool> = (0..9 * w * h)
        .map(|i| drawn(i % (3 * w), i / (3 * w)))
        .collect();
    Ok(falloff(&on, w, h, p.radius))
}

/// `F = 1 − min(d, radius) / radius` over the centre tile of the 3 × 3 tiling `on`
/// (`3w × 3h`, true on feature texels), `d` the distance to the nearest feature texel.
fn falloff(on: &[bool], w: usize, h: usize, radius: f32) -> Vec<f32> {
    let d = distance_transform(on, 3 * w as u32, 3 * h as u32);
    let mut out = Vec::with_capacity(w * h);
    for y in h..2 * h {
        for x in w..2 * w {
            let dist = d[y * 3 * w + x];
            out.push(1.0 - dist.min(radius) / radius);
        }
    }
    out
}

/// The exemplar in appearance space (module docs, steps 1–3), its feature curves drawn in
/// `mask` (the exemplar's size) or else detected.
pub fn appearance(
    img: ImageView,
    mask: Option<ImageView>,
    p: &FeatureMaskParams,
) -> Result<Appearance, String> {
    let channel = match mask {
        Some(m) => drawn_channel(m, p)?,
        None => feature_channel(img, p)?,
    };
    let mut data = Vec::with_capacity(4 * channel.len());
    for (c, f) in img.pixels.iter().zip(&channel) {
        data.extend_from_slice(&[c[0], c[1], c[2], p.weight * f]);
    }
    let pca = Pca::fit(
        &data,
        4,
        &PcaParams {
            components: 3,
            ..Default::default()
        },
    );
    let proj = pca.project_all(&data);
    let k = pca.components();
    let total: f32 = variance(&data, 4).iter().sum();
    let kept: f32 = variance(&proj, k).iter().sum();
    let mut image = Image::new(img.width, img.height);
    for (px, v) in image.pixels.iter_mut().zip(proj.chunks_exact(k)) {
        let mut c = [0.0, 0.0, 0.0, 1.0];
        c[..k].copy_from_slice(v);
        *px = c;
    }
    Ok(Appearance {
        channel,
        image,
        kept_variance: if total > 0.0 { kept / total } else { 1.0 },
    })
}

/// Per-dimension variance of row vectors of length `dim`.
fn variance(data: &[f32], dim: usize) -> Vec<f32> {
    let n = (data.len() / dim).max(1) as f64;
    let mut mean = vec![0.0f64; dim];
    for v in data.chunks_exact(dim) {
        for (m, x) in mean.iter_mut().zip(v) {
            *m += *x as f64;
        }
    }
    mean.iter_mut().for_each(|m| *m /= n);
    let mut var = vec![0.0f64; dim];
    for v in data.chunks_exact(dim) {
        for ((s, x), m) in var.iter_mut().zip(v).zip(&mean) {
            let d = *x as f64 - m;
            *s += d * d;
        }
    }
    var.iter().map(|s| (s / n) as f32).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A brick-like pattern: light bricks, dark one-texel mortar rows every 8 texels and
    /// joints every 16, offset by half a brick on alternate rows.
    fn bricks(w: u32, h: u32) -> Image {
        Image::from_fn(w, h, |x, y| {
            let row = y / 8;
            let xs = (x + row % 2 * 8) % 16;
            let mortar = y % 8 == 0 || xs == 0;
            if mortar {
                [0.15, 0.15, 0.15, 1.0]
            } else {
                [0.7, 0.4, 0.3, 1.0]
            }
        })
    }

    #[test]
    fn the_channel_is_high_on_mortar_and_wraps_around() {
        let img = bricks(32, 32);
        let f = feature_channel(img.view(), &FeatureMaskParams::default()).unwrap();
        let at = |x: usize, y: usize| f[y * 32 + x];
        // On a mortar row (also the first row: it wraps to the last) and far from one.
        assert!(
            at(5, 8) > 0.99 && at(5, 0) > 0.99,
            "{} {}",
            at(5, 8),
            at(5, 0)
        );
        assert!(at(5, 4) < at(5, 2) && at(5, 2) < at(5, 1));
        // Row 31 is one texel from row 0's mortar across the wrap.
        assert!((at(5, 31) - at(5, 1)).abs() < 1e-6);
    }

    #[test]
    fn appearance_separates_mortar_from_equally_dark_brick() {
        // A dark brick texel and a mortar texel of the same colour get different appearances
        // with the channel, the same without it.
        let mut img = bricks(32, 32);
        img.pixels[4 * 32 + 4] = [0.15, 0.15, 0.15, 1.0];
        let p = FeatureMaskParams {
            weight: 2.0,
            ..Default::default()
        };
        let a = appearance(img.view(), None, &p).unwrap();
        let (brick, mortar) = (a.image.pixels[4 * 32 + 4], a.image.pixels[8 * 32 + 4]);
        let d: f32 = (0..3)
            .map(|k| (brick[k] - mortar[k]) * (brick[k] - mortar[k]))
            .sum();
        assert!(d > 0.5, "appearance distance {d}");
        assert!(a.kept_variance > 0.9, "{}", a.kept_variance);
    }

    #[test]
    fn a_drawn_mask_is_the_curves_and_its_distances_wrap_around() {
        // One drawn column, x = 3, of a 16 × 12 mask.
        let mask = Image::from_fn(16, 12, |x, _| {
            let v = if x == 3 { 0.8 } else { 0.1 };
            [v, v, v, 1.0]
        });
        let p = FeatureMaskParams::default();
        let f = drawn_channel(mask.view(), &p).unwrap();
        let at = |x: usize, y: usize| f[y * 16 + x];
        assert_eq!(at(3, 5), 1.0);
        assert!(
            (at(5, 5) - (1.0 - 2.0 / p.radius)).abs() < 1e-5,
            "{}",
            at(5, 5)
        );
        // x = 15 is 4 texels from x = 3 across the wrap (12 the other way).
        assert!(
            (at(15, 0) - (1.0 - 4.0 / p.radius)).abs() < 1e-5,
            "{}",
            at(15, 0)
        );
        assert_eq!(at(10, 7), 0.0);
        // The drawn curves replace the detector: the same image, other channels.
        let img = bricks(16, 12);
        let drawn = appearance(img.view(), Some(mask.view()), &p).unwrap();
        let detected = appearance(img.view(), None, &p).unwrap();
        assert_eq!(drawn.channel, f);
        assert_ne!(drawn.channel, detected.channel);
        let blank = Image::from_fn(16, 12, |_, _| [0.2, 0.2, 0.2, 1.0]);
        let e = drawn_channel(blank.view(), &p).unwrap_err();
        assert!(e.contains("no feature texel"), "{e}");
    }

    #[test]
    fn an_exemplar_without_lines_is_an_error() {
        let img = Image::from_fn(16, 16, |_, _| [0.5, 0.5, 0.5, 1.0]);
        let e = feature_channel(img.view(), &FeatureMaskParams::default()).unwrap_err();
        assert!(e.contains("no feature lines"), "{e}");
    }
}
