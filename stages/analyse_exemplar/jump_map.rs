//! Jump maps: for every exemplar pixel, a short weighted list of other pixels whose
//! neighbourhoods look like its own.
//!
//! Implements the analysis phase of S. Zelinka and M. Garland, "Towards real-time texture
//! synthesis with the jump map", Eurographics Workshop on Rendering 2002, as summarized in §4.2.1
//! and §4.2.5 of Zelinka and Garland, "Interactive texture synthesis on surfaces using jump maps"
//! (2003): each pixel is described by Gaussian-weighted neighbourhoods over a few levels of a
//! Gaussian pyramid, the descriptors are reduced by PCA, and a kd-tree finds the best matches.
//! Jump weights are "normalized to sum to one, or a lower value if the jumps at that pixel were
//! not very good".
//!
//! Departures and choices the papers leave open:
//! - Matches come from an approximate kd-tree search (`search_eps`, default 2: a reported match
//!   is at most 3× farther than the true one; 0 = exact). The 2002 paper used approximate
//!   search too. Measured on marble1 (128²) and grass_512, eps = 2 raised the mean 5×5 colour
//!   distance of the best jumps by about 1% and cut the analysis time 3.5× and 13× (16-D PCA
//!   spaces are hard for exact kd-tree search: 85 s exact for grass_512 on two cores).
//! - Pyramid levels are weighted `coarse_weight^level` (default 0.5), not equally: equal weights
//!   let the blurred coarse levels outvote fine detail; halving per level lowered the best
//!   jumps' 5×5 colour distance by 7–16% on the test exemplars.
//! - Spatially close matches are excluded inside the search (a filtered kNN) instead of by
//!   post-filtering a longer list, and a match within `exclusion_radius` of a better match
//!   already chosen for the same pixel is skipped as well, so the k jumps lead to k different
//!   places.
//! - Similarity is `s = exp(-d² / 2σ²)`, with `d` the feature distance and σ the median over
//!   pixels of the best jump's distance; weights are `s / max(1, Σ s)`, and never below
//!   [`MIN_WEIGHT`] so that a found jump is never mistaken for an empty slot.
//! - The PCA basis is fitted on at most `pca_samples` pixels (a regular subsample), then applied
//!   to every pixel.
//!
//! Output is identical for any number of threads: neighbourhoods, PCA and kd-tree are
//! deterministic and every pixel's search writes only its own slots.

use crate::check::{ParamError, check_range};
use crate::image::ImageView;
use crate::image::knn::KdTree;
use crate::image::neighbourhood::{NeighbourhoodParams, Neighbourhoods, level_window};
use crate::image::pca::{Pca, PcaParams};
use rayon::prelude::*;
use texsyn_core::algorithm::Failure;
use texsyn_core::math::PureMath;

/// The `jump_map` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("jump_map", 1);

/// The smallest weight a found jump gets (weight 0 marks an unused slot).
pub const MIN_WEIGHT: f32 = 1e-9;

/// Largest exemplar side: addresses are stored as u16.
pub const MAX_EXEMPLAR_SIDE: u32 = u16::MAX as u32 + 1;

/// One jump: a destination pixel and its weight. `weight == 0` marks an unused slot.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Jump {
    pub x: u16,
    pub y: u16,
    pub weight: f32,
}

/// Parameters of the jump-map analysis.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct JumpMapParams {
    /// Gaussian pyramid levels compared, 1..=8 (fewer are used if the exemplar is too small to
    /// have them). Default: 3.
    pub levels: u32,
    /// Neighbourhood window side at the finest level, odd, 1..=15; coarser levels use
    /// `window - 2·level`, at least 3. A window whose descriptor on the exemplar is longer than
    /// [`MAX_DESCRIPTOR_LEN`] numbers is refused when the analysis starts ([`check_descriptor`]).
    /// Default: 5.
    pub window: u32,
    /// Weight of each pyramid level relative to the next finer one, 0..=1. Default: 0.5.
    pub coarse_weight: f32,
    /// PCA components kept, 0..=64; 0 = automatic (the fewest explaining 95% of the variance,
    /// at least 4, at most 16). Default: 0.
    pub pca_dims: u32,
    /// Jumps stored per pixel (k), 1..=32. Default: 4.
    pub jumps_per_pixel: u32,
    /// In pixels, 0..=10000: jumps go farther than this from their source pixel and from each
    /// other. Default: 4.
    pub exclusion_radius: f32,
    /// Pixels used to fit the PCA basis, 256..=16777216 (a regular subsample if the exemplar
    /// has more). Default: 65536.
    pub pca_samples: u32,
    /// Approximate-search factor, 0..=10: a found match is at most `1 + search_eps` times
    /// farther than the true one. 0 = exact. Default: 2.
    pub search_eps: f32,
}

impl Default for JumpMapParams {
    fn default() -> Self {
        JumpMapParams {
            levels: 3,
            window: 5,
            coarse_weight: 0.5,
            pca_dims: 0,
            jumps_per_pixel: 4,
            exclusion_radius: 4.0,
            pca_samples: 65536,
            search_eps: 2.0,
        }
    }
}

impl JumpMapParams {
    /// Checks every field's range; the error names the field, its range and the value.
    pub fn validate(&self) -> Result<(), ParamError> {
        // Finite bounds: NaN and infinities fail the range check too.
        let range = |name: &str, v, lo, hi| {
            check_range::<u32>(name, v, lo, hi).map_err(|e| e.within("jump map"))
        };
        let rangef = |name: &str, v, lo, hi| {
            check_range::<f32>(name, v, lo, hi).map_err(|e| e.within("jump map"))
        };
        range("levels", self.levels, 1, 8)?;
        range("window", self.window, 1, 15)?;
        if self.window.is_multiple_of(2) {
            return Err(ParamError::invalid(
                "window",
                format!("must be odd (1..=15), got {}", self.window),
            )
            .within("jump map"));
        }
        rangef("coarse_weight", self.coarse_weight, 0.0, 1.0)?;
        range("pca_dims", self.pca_dims, 0, 64)?;
        range("jumps_per_pixel", self.jumps_per_pixel, 1, 32)?;
        rangef("exclusion_radius", self.exclusion_radius, 0.0, 10000.0)?;
        range("pca_samples", self.pca_samples, 256, 1 << 24)?;
        rangef("search_eps", self.search_eps, 0.0, 10.0)
    }
}

/// Why an exemplar or a stored jump map cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum JumpMapError {
    #[error(
        "jump map: exemplar must be 1..={MAX_EXEMPLAR_SIDE} pixels on each side, got {width}×{height}"
    )]
    ExemplarSize { width: u32, height: u32 },
    #[error("jump map: {width}×{height} with {k} jumps per pixel needs {want} slots, got {got}")]
    SlotCount {
        width: u32,
        height: u32,
        k: u32,
        want: u64,
        got: usize,
    },
    #[error("jump map: slot {slot} is not a valid jump: {jump:?}")]
    BadJump { slot: usize, jump: Jump },
    #[error(
        "jump map: analyse_exemplar.window = {window} over {levels} pyramid levels compares \
         {len}-number neighbourhoods, more than the {MAX_DESCRIPTOR_LEN} whose analysis takes \
         about 70 s on 2 cores (its PCA grows faster than the cube of the length: window 15 \
         over 3 levels took about 25 minutes); the largest window that fits is {fits}"
    )]
    DescriptorTooLong {
        window: u32,
        levels: usize,
        len: usize,
        fits: u32,
    },
}

/// The longest neighbourhood descriptor the analysis accepts, in numbers: window 13 over 3
/// levels (13² + 11² + 9² RGB texels). On the 64×62 leopard, 2 cores: window 9 (465 numbers)
/// 2.6 s, 11 (753) 12.7 s, 13 (1113) 70 s, 15 (1545) about 25 minutes, the cyclic Jacobi
/// eigendecomposition of the covariance dominating.
pub const MAX_DESCRIPTOR_LEN: usize = 1113;

/// Length of the neighbourhood descriptor of finest window `window` over `levels` levels.
pub fn descriptor_len(window: u32, levels: usize) -> usize {
    (0..levels)
        .map(|l| 3 * level_window(window.max(1) | 1, l).pow(2) as usize)
        .sum()
}

/// Pyramid levels an exemplar of `width × height` gets for `levels` asked (as
/// [`Pyramid::build`](crate::image::pyramid::Pyramid::build) stops).
fn pyramid_levels(width: u32, height: u32, levels: u32) -> usize {
    let (mut w, mut h, mut n) = (width, height, 1usize);
    while n < levels.max(1) as usize {
        let (nw, nh) = (w.div_ceil(2), h.div_ceil(2));
        if nw.min(nh) < crate::image::pyramid::MIN_LEVEL_SIDE || w < 2 || h < 2 {
            break;
        }
        (w, h, n) = (nw, nh, n + 1);
    }
    n
}

/// Refuses a window whose descriptor on this exemplar is longer than [`MAX_DESCRIPTOR_LEN`],
/// naming the largest window that fits.
pub fn check_descriptor(
    width: u32,
    height: u32,
    params: &JumpMapParams,
) -> Result<(), JumpMapError> {
    let levels = pyramid_levels(width, height, params.levels);
    let len = descriptor_len(params.window, levels);
    if len <= MAX_DESCRIPTOR_LEN {
        return Ok(());
    }
    let fits = (1..=params.window)
        .rev()
        .step_by(2)
        .find(|&w| descriptor_len(w, levels) <= MAX_DESCRIPTOR_LEN)
        .unwrap_or(1);
    Err(JumpMapError::DescriptorTooLong {
        window: params.window,
        levels,
        len,
        fits,
    })
}

/// Checks that an exemplar can have a jump map (addresses are u16).
pub fn check_exemplar_size(width: u32, height: u32) -> Result<(), JumpMapError> {
    if width == 0 || height == 0 || width > MAX_EXEMPLAR_SIDE || height > MAX_EXEMPLAR_SIDE {
        return Err(JumpMapError::ExemplarSize { width, height });
    }
    Ok(())
}

/// A jump map: `k` slots per exemplar pixel, row-major, best jump first, unused slots (weight
/// 0) last.
#[derive(Clone, Debug, PartialEq)]
pub struct JumpMap {
    pub width: u32,
    pub height: u32,
    pub k: u32,
    pub jumps: Vec<Jump>,
}

/// A borrowed jump map, e.g. viewed in place in a mapped artifact.
#[derive(Clone, Copy, Debug)]
pub struct JumpMapRef<'a> {
    pub width: u32,
    pub height: u32,
    pub k: u32,
    pub jumps: &'a [Jump],
}

impl JumpMap {
    pub fn as_ref(&self) -> JumpMapRef<'_> {
        JumpMapRef {
            width: self.width,
            height: self.height,
            k: self.k,
            jumps: &self.jumps,
        }
    }

    /// The used jumps of pixel `(x, y)`, best first.
    pub fn jumps_at(&self, x: u32, y: u32) -> &[Jump] {
        self.as_ref().jumps_at(x, y)
    }
}

impl<'a> JumpMapRef<'a> {
    /// Checks sizes and contents of data from outside (an artifact): the slot count matches,
    /// every used jump lies inside the exemplar, weights are finite and non-negative.
    pub fn new(width: u32, height: u32, k: u32, jumps: &'a [Jump]) -> Result<Self, JumpMapError> {
        check_exemplar_size(width, height)?;
        let want = width as u64 * height as u64 * k as u64;
        if jumps.len() as u64 != want {
            return Err(JumpMapError::SlotCount {
                width,
                height,
                k,
                want,
                got: jumps.len(),
            });
        }
        if let Some(i) = jumps.iter().position(|j| {
            !(j.weight.is_finite() && j.weight >= 0.0)
                || (j.weight > 0.0 && (j.x as u32 >= width || j.y as u32 >= height))
        }) {
            return Err(JumpMapError::BadJump {
                slot: i,
                jump: jumps[i],
            });
        }
        Ok(JumpMapRef {
            width,
            height,
            k,
            jumps,
        })
    }

    /// The used jumps of pixel `(x, y)` (those with weight > 0), best first.
    #[inline]
    pub fn jumps_at(&self, x: u32, y: u32) -> &'a [Jump] {
        let k = self.k as usize;
        let i = (y as usize * self.width as usize + x as usize) * k;
        let slots = &self.jumps[i..i + k];
        let used = slots.iter().take_while(|j| j.weight > 0.0).count();
        &slots[..used]
    }
}

/// Builds the jump map of `img` (see the module docs). `progress` is called from the calling
/// thread with the fraction done, from 0 to 1.
///
/// Panics if a side of `img` exceeds [`MAX_EXEMPLAR_SIDE`] (see [`check_exemplar_size`]) or if
/// `params` do not pass [`JumpMapParams::validate`]; callers check both first.
pub fn build_jump_map(img: ImageView, params: &JumpMapParams, progress: &dyn Fn(f32)) -> JumpMap {
    if let Err(e) = params.validate() {
        panic!("{e}");
    }
    let (w, h) = (img.width, img.height);
    let k = params.jumps_per_pixel as usize;
    let n = w as usize * h as usize;
    progress(0.0);
    if n == 0 {
        progress(1.0);
        return JumpMap {
            width: w,
            height: h,
            k: k as u32,
            jumps: Vec::new(),
        };
    }
    if let Err(e) = check_exemplar_size(w, h) {
        panic!("{e}");
    }

    // 1. Neighbourhood descriptors, reduced by PCA.
    let nb = Neighbourhoods::new(
        img,
        &NeighbourhoodParams {
            levels: params.levels,
            window: params.window,
            coarse_weight: params.coarse_weight,
        },
    );
    let dim = nb.dim();
    let stride = n.div_ceil(params.pca_samples as usize).max(1);
    let sample_count = n.div_ceil(stride);
    let mut samples = vec![0.0f32; sample_count * dim];
    samples.par_chunks_mut(dim).enumerate().for_each(|(s, v)| {
        let i = s * stride;
        nb.write((i % w as usize) as u32, (i / w as usize) as u32, v);
    });
    let pca = Pca::fit(
        &samples,
        dim,
        &PcaParams {
            components: params.pca_dims,
            ..PcaParams::default()
        },
    );
    drop(samples);
    let d = pca.components();
    let mut reduced = vec![0.0f32; n * d];
    reduced
        .par_chunks_mut(w as usize * d)
        .enumerate()
        .for_each(|(y, row)| {
            let mut feat = vec![0.0f32; dim];
            for (x, out) in row.chunks_mut(d).enumerate() {
                nb.write(x as u32, y as u32, &mut feat);
                pca.project(&feat, out);
            }
        });
    drop(nb);
    tracing::debug!(
        target: "texsyn::jump_map",
        dim,
        components = d,
        explained = pca.explained_variance(),
        "neighbourhood PCA"
    );
    progress(0.15);

    // 2. Matches.
    let tree = KdTree::build(&reduced, d);
    let r2 = params.exclusion_radius * params.exclusion_radius;
    let eps = params.search_eps;
    let mut found: Vec<(u32, f32)> = vec![(u32::MAX, f32::INFINITY); n * k];
    let batches = 20usize;
    let rows_per_batch = (h as usize).div_ceil(batches).max(1);
    for (b, chunk) in found
        .chunks_mut(rows_per_batch * w as usize * k)
        .enumerate()
    {
        let y0 = b * rows_per_batch;
        chunk
            .par_chunks_mut(w as usize * k)
            .enumerate()
            .for_each(|(dy, row)| {
                let y = (y0 + dy) as u32;
                let mut chosen: Vec<(u32, u32)> = Vec::with_capacity(k);
                for (x, slots) in row.chunks_mut(k).enumerate() {
                    let i = y as usize * w as usize + x;
                    let q = &reduced[i * d..(i + 1) * d];
                    find_jumps(&tree, q, (x as u32, y), w, r2, eps, &mut chosen, slots);
                }
            });
        progress(0.15 + 0.8 * ((b + 1) * rows_per_batch).min(h as usize) as f32 / h as f32);
    }

    // 3. Weights.
    let mut best: Vec<f32> = found
        .chunks(k)
        .filter(|s| s[0].0 != u32::MAX)
        .map(|s| s[0].1.sqrt())
        .collect();
    best.sort_by(|a, b| a.total_cmp(b));
    let sigma = if best.is_empty() {
        0.0
    } else {
        best[best.len() / 2] as f64
    };
    let mut jumps = vec![
        Jump {
            x: 0,
            y: 0,
            weight: 0.0,
        };
        n * k
    ];
    jumps
        .par_chunks_mut(k)
        .zip(found.par_chunks(k))
        .for_each(|(out, slots)| {
            let mut sims = [0.0f64; 32];
            for (s, &(id, d2)) in sims.iter_mut().zip(slots) {
                *s = if id == u32::MAX {
                    0.0
                } else if sigma > 0.0 {
                    (-(d2 as f64) / (2.0 * sigma * sigma)).exp_pure()
                } else if d2 == 0.0 {
                    1.0
                } else {
                    0.0
                };
            }
            let norm = sims[..k].iter().sum::<f64>().max(1.0);
            for ((o, &(id, _)), &s) in out.iter_mut().zip(slots).zip(&sims) {
                if id != u32::MAX {
                    *o = Jump {
                        x: (id % w) as u16,
                        y: (id / w) as u16,
                        weight: ((s / norm) as f32).max(MIN_WEIGHT),
                    };
                }
            }
        });
    progress(1.0);
    JumpMap {
        width: w,
        height: h,
        k: k as u32,
        jumps,
    }
}

#[inline]
fn far(a: (u32, u32), b: (u32, u32), r2: f32) -> bool {
    let dx = a.0 as f32 - b.0 as f32;
    let dy = a.1 as f32 - b.1 as f32;
    dx * dx + dy * dy > r2
}

/// Fills `slots` with the best matches of pixel `p` (descriptor `q`): nearest first, each
/// farther than the exclusion radius from `p` and from every better match. This is exactly the
/// greedy sequential definition; candidate lists are fetched in blocks to save searches.
#[allow(clippy::too_many_arguments)]
fn find_jumps(
    tree: &KdTree,
    q: &[f32],
    p: (u32, u32),
    w: u32,
    r2: f32,
    eps: f32,
    chosen: &mut Vec<(u32, u32)>,
    slots: &mut [(u32, f32)],
) {
    let k = slots.len();
    chosen.clear();
    let mut filled = 0;
    while filled < k {
        let want = 2 * (k - filled) + 2;
        let cands = tree.as_ref().nearest_approx(q, want, eps, |id| {
            let c = (id % w, id / w);
            far(c, p, r2) && chosen.iter().all(|&o| far(c, o, r2))
        });
        let exhausted = cands.len() < want;
        // Candidates passed the filter for the jumps chosen before this search; check them
        // against the ones chosen from this list.
        let before = chosen.len();
        for &(id, d2) in &cands {
            if filled == k {
                break;
            }
            let c = (id % w, id / w);
            if chosen[before..].iter().all(|&o| far(c, o, r2)) {
                chosen.push(c);
                slots[filled] = (id, d2);
                filled += 1;
            }
        }
        if exhausted {
            break;
        }
    }
    // Approximate searches may find, in a later block, a match closer than one found earlier.
    slots[..filled].sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
}

/// The analyse-exemplar node (§2): the exemplar's jump map, for an exemplar big enough to
/// have one.
pub fn node(
    img: ImageView,
    params: &JumpMapParams,
    progress: &dyn Fn(f32),
) -> Result<JumpMap, Failure> {
    check_exemplar_size(img.width, img.height).map_err(Failure::input)?;
    check_descriptor(img.width, img.height, params).map_err(Failure::input)?;
    Ok(build_jump_map(img, params, progress))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::assert_validation;

    #[test]
    fn default_params_are_valid_and_bad_ones_named() {
        assert_validation!(JumpMapParams {
            window: 4 => "jump map: window must be odd (1..=15), got 4",
            jumps_per_pixel: 0 => "jump map: jumps_per_pixel must be in 1..=32, got 0",
            exclusion_radius: f32::NAN =>
                "jump map: exclusion_radius must be in 0..=10000, got NaN",
        });
    }

    #[test]
    fn a_window_whose_analysis_would_take_minutes_is_refused_naming_one_that_fits() {
        let p = |window, levels| JumpMapParams {
            window,
            levels,
            ..Default::default()
        };
        // The measured cases: 13 over 3 levels fits, 15 does not and names 13.
        assert_eq!(descriptor_len(13, 3), 1113);
        assert!(check_descriptor(64, 62, &p(13, 3)).is_ok());
        let e = check_descriptor(64, 62, &p(15, 3)).unwrap_err();
        assert_eq!(
            e,
            JumpMapError::DescriptorTooLong {
                window: 15,
                levels: 3,
                len: 1545,
                fits: 13
            }
        );
        assert!(
            e.to_string().contains("the largest window that fits is 13"),
            "{e}"
        );
        // More levels make the descriptor longer: 13 over 6 levels of a 512² exemplar is
        // refused, 11 fits.
        let e = check_descriptor(512, 512, &p(13, 6)).unwrap_err();
        assert!(
            matches!(e, JumpMapError::DescriptorTooLong { fits: 11, .. }),
            "{e}"
        );
        // A 12² exemplar has one level, where window 15 fits.
        assert!(check_descriptor(12, 12, &p(15, 3)).is_ok());
    }

    #[test]
    fn ref_checks_lengths_and_addresses() {
        let j = vec![
            Jump {
                x: 1,
                y: 0,
                weight: 0.5
            };
            4
        ];
        assert!(JumpMapRef::new(2, 2, 1, &j).is_ok());
        assert!(JumpMapRef::new(2, 2, 2, &j).is_err());
        let mut bad = j.clone();
        bad[3].x = 2;
        assert!(
            JumpMapRef::new(2, 2, 1, &bad)
                .unwrap_err()
                .to_string()
                .contains("slot 3")
        );
    }
}
