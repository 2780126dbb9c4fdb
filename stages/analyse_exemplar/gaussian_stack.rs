//! The exemplar's Gaussian stack or pyramid for region matching (Bangay & Morkel, "Graph
//! Matching with Subdivision Surfaces for Texture Synthesis on Surfaces", §3.3.1: "We perform
//! matching at multiple resolutions using a Gaussian image stack [Lefebvre and Hoppe 2005] …
//! The matching process is equally applicable to image pyramids"; §3.3.2: `a = 1` for a stack,
//! `2` for a pyramid).
//!
//! Level 0 is the exemplar. A stack keeps every level at full size: level `m` is level `m − 1`
//! blurred by the 5-tap binomial with its taps `2^(m−1)` texels apart (à trous), so level `m`
//! holds features of about `2^m` texels at every texel position, as Lefebvre & Hoppe's stack
//! does. A pyramid halves each level ([`crate::image::pyramid::downsample`]).
//!
//! Texel addresses are in level-0 (finest) texels everywhere; level `m` of a pyramid holds the
//! texel of finest address `x` at `x / 2^m` ([`GaussianStackRef::texel`]). Borders are clamped:
//! exemplars are not assumed to tile.
//!
//! Only RGB is kept: the paper's "colour" (or a grey displacement value, which is R = G = B).

use crate::check::{ParamError, check_range};
use crate::image::ImageView;
use serde::{Deserialize, Serialize};
use texsyn_core::algorithm::Failure;

/// The `gaussian_stack` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("gaussian_stack", 1);

/// Stack or pyramid (the paper's `a`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StackKind {
    /// Every level at full size (`a = 1`): no quantization of positions between levels.
    #[default]
    Stack,
    /// Every level half the size of the one before (`a = 2`): less to search.
    Pyramid,
}

/// `[analyse_exemplar]` of the graph-matching method.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StackParams {
    /// `"stack"` (default) or `"pyramid"`.
    pub kind: StackKind,
    /// Levels, 1..=10; 0 = as many as the exemplar allows (until a level's features are as
    /// large as a quarter of its shorter side). Default: 0.
    pub levels: u32,
}

impl Default for StackParams {
    fn default() -> Self {
        StackParams {
            kind: StackKind::Stack,
            levels: 0,
        }
    }
}

impl StackParams {
    pub fn validate(&self) -> Result<(), ParamError> {
        check_range("analyse_exemplar.levels", self.levels, 0, 10)
    }
}

/// Why an exemplar cannot be analysed.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum StackError {
    #[error("inputs.exemplar is {width}×{height} texels; graph matching needs at least 8×8")]
    TooSmall { width: u32, height: u32 },
}

/// Per-level sizes and the stack's factor `a`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StackMeta {
    /// (width, height) of each level, finest first.
    pub sizes: Vec<(u32, u32)>,
    /// 1 for a stack, 2 for a pyramid.
    pub factor: u32,
}

/// The levels' RGB texels, finest first, each level row by row.
#[derive(Clone, Debug, PartialEq)]
pub struct GaussianStack {
    pub meta: StackMeta,
    pub texels: Vec<[f32; 3]>,
}

/// A stack as a reader sees it (borrowed from the artifact).
#[derive(Clone, Copy, Debug)]
pub struct GaussianStackRef<'a> {
    pub meta: &'a StackMeta,
    pub texels: &'a [[f32; 3]],
}

impl GaussianStack {
    pub fn view(&self) -> GaussianStackRef<'_> {
        GaussianStackRef {
            meta: &self.meta,
            texels: &self.texels,
        }
    }
}

/// Builds the stack (or pyramid) of `exemplar`.
pub fn build_stack(exemplar: ImageView, p: &StackParams) -> Result<GaussianStack, StackError> {
    let (w, h) = (exemplar.width, exemplar.height);
    if w.min(h) < 8 {
        return Err(StackError::TooSmall {
            width: w,
            height: h,
        });
    }
    let levels = if p.levels == 0 {
        auto_levels(w, h)
    } else {
        p.levels
    };
    let mut images = vec![exemplar.to_owned()];
    for m in 1..levels {
        let prev = images.last().expect("level 0").view();
        let next = match p.kind {
            StackKind::Stack => crate::image::pyramid::blur_binomial5_dilated(prev, 1 << (m - 1)),
            StackKind::Pyramid => {
                if prev.width.min(prev.height) < 4 {
                    break;
                }
                crate::image::pyramid::downsample(prev)
            }
        };
        images.push(next);
    }
    let sizes = images.iter().map(|i| (i.width, i.height)).collect();
    let texels = images
        .iter()
        .flat_map(|i| i.pixels.iter().map(|p| [p[0], p[1], p[2]]))
        .collect();
    Ok(GaussianStack {
        meta: StackMeta {
            sizes,
            factor: match p.kind {
                StackKind::Stack => 1,
                StackKind::Pyramid => 2,
            },
        },
        texels,
    })
}

/// Levels until features reach a quarter of the shorter side: `log2(min side) − 1`, at most 8.
fn auto_levels(w: u32, h: u32) -> u32 {
    (31 - w.min(h).leading_zeros())
        .saturating_sub(1)
        .clamp(1, 8)
}

impl<'a> GaussianStackRef<'a> {
    pub fn levels(&self) -> usize {
        self.meta.sizes.len()
    }

    /// The finest level's size.
    pub fn size(&self) -> (u32, u32) {
        self.meta.sizes[0]
    }

    /// How many finest texels one texel of level `m` spans (`a^m`).
    pub fn spacing(&self, m: usize) -> u32 {
        self.meta.factor.pow(m as u32)
    }

    /// Index of the first texel of level `m` in `texels`.
    pub fn level_start(&self, m: usize) -> usize {
        self.meta.sizes[..m]
            .iter()
            .map(|&(w, h)| w as usize * h as usize)
            .sum()
    }

    /// The texel index (into `texels`) of level `m` nearest to finest address `(x, y)`,
    /// clamped to the level.
    #[inline]
    pub fn texel(&self, m: usize, start: usize, x: f32, y: f32) -> usize {
        let (w, h) = self.meta.sizes[m];
        let s = self.spacing(m) as f32;
        let ix = ((x / s).round() as i64).clamp(0, w as i64 - 1) as usize;
        let iy = ((y / s).round() as i64).clamp(0, h as i64 - 1) as usize;
        start + iy * w as usize + ix
    }

    /// The colour of level `m` at finest address `(x, y)` (nearest texel, clamped).
    pub fn colour(&self, m: usize, x: f32, y: f32) -> [f32; 3] {
        self.texels[self.texel(m, self.level_start(m), x, y)]
    }

    /// Checks the arrays against the metadata (a damaged artifact is an error, never a bad
    /// index later).
    pub fn is_consistent(&self) -> bool {
        let sizes = &self.meta.sizes;
        let mut n = 0usize;
        for &(w, h) in sizes {
            match (w as usize)
                .checked_mul(h as usize)
                .and_then(|a| n.checked_add(a))
            {
                Some(total) if w > 0 && h > 0 => n = total,
                _ => return false,
            }
        }
        !sizes.is_empty()
            && sizes.len() <= MAX_LEVELS
            && (self.meta.factor == 1 || self.meta.factor == 2)
            && n == self.texels.len()
            && self.texels.iter().all(|t| t.iter().all(|c| c.is_finite()))
    }
}

/// More levels than any exemplar can have (sides up to 2^30): a bound for damaged artifacts.
const MAX_LEVELS: usize = 30;

/// The analyse-exemplar node: the exemplar's Gaussian stack.
pub fn node(exemplar: ImageView, p: &StackParams) -> Result<GaussianStack, Failure> {
    build_stack(exemplar, p).map_err(Failure::input)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Image;

    fn stripes(w: u32, h: u32, period: u32) -> Image {
        Image::from_fn(w, h, |x, _| {
            let v = if (x / period).is_multiple_of(2) {
                1.0
            } else {
                0.0
            };
            [v, v, v, 1.0]
        })
    }

    /// The variance of the red channel away from the borders (where clamping keeps detail).
    fn variance(s: GaussianStackRef, m: usize) -> f32 {
        let start = s.level_start(m);
        let (w, h) = s.meta.sizes[m];
        let px: Vec<[f32; 3]> = (8..h - 8)
            .flat_map(|y| (8..w - 8).map(move |x| (y * w + x) as usize))
            .map(|i| s.texels[start + i])
            .collect();
        let mean = px.iter().map(|p| p[0]).sum::<f32>() / px.len() as f32;
        px.iter().map(|p| (p[0] - mean).powi(2)).sum::<f32>() / px.len() as f32
    }

    #[test]
    fn stack_levels_keep_the_size_and_remove_finer_features_first() {
        // Stripes 2 texels wide vanish by level 2; stripes 16 wide survive it.
        let fine = build_stack(stripes(64, 64, 2).view(), &StackParams::default()).unwrap();
        let coarse = build_stack(stripes(64, 64, 16).view(), &StackParams::default()).unwrap();
        let (f, c) = (fine.view(), coarse.view());
        assert_eq!(f.levels(), 5);
        assert!(f.meta.sizes.iter().all(|&s| s == (64, 64)));
        assert!(f.is_consistent());
        assert!(variance(f, 2) < 0.01 * variance(f, 0));
        assert!(variance(c, 2) > 0.5 * variance(c, 0));
        // Blurring keeps the mean: constant images stay constant.
        let flat = Image::from_fn(16, 16, |_, _| [0.3, 0.6, 0.9, 1.0]);
        let s = build_stack(flat.view(), &StackParams::default()).unwrap();
        assert!(
            s.texels
                .iter()
                .all(|t| (t[0] - 0.3).abs() < 1e-5 && (t[2] - 0.9).abs() < 1e-5)
        );
    }

    #[test]
    fn pyramid_levels_halve_and_addresses_are_in_finest_texels() {
        let img = Image::from_fn(64, 32, |x, y| [x as f32 / 64.0, y as f32 / 32.0, 0.0, 1.0]);
        let p = StackParams {
            kind: StackKind::Pyramid,
            levels: 3,
        };
        let s = build_stack(img.view(), &p).unwrap();
        let v = s.view();
        assert_eq!(v.meta.sizes, vec![(64, 32), (32, 16), (16, 8)]);
        assert_eq!(v.spacing(2), 4);
        // Finest address (40, 20) is texel (10, 5) of level 2, where the ramp reads about 40/64.
        let c = v.colour(2, 40.0, 20.0);
        assert!((c[0] - 40.0 / 64.0).abs() < 0.02, "{c:?}");
        assert!((c[1] - 20.0 / 32.0).abs() < 0.04, "{c:?}");
        // Clamped outside.
        assert_eq!(v.colour(0, -5.0, 1000.0), v.colour(0, 0.0, 31.0));
    }

    #[test]
    fn tiny_exemplars_are_refused() {
        let img = Image::from_fn(6, 40, |_, _| [0.0; 4]);
        assert_eq!(
            build_stack(img.view(), &StackParams::default()),
            Err(StackError::TooSmall {
                width: 6,
                height: 40
            })
        );
    }
}
