//! Nearest-patch quality measures of a synthesized image against its exemplar (the numbers a
//! `texsyn score` reports):
//!
//! - every `p × p` patch of the output (or a seeded subset of at most `max_queries` of them)
//!   is matched to its exact nearest `p × p` patch of the exemplar, by RMS distance over the
//!   RGB values (clamped to [0, 1]): `sqrt(sum of squared differences / (p·p·3))`;
//! - `ratio` divides the mean of those distances by a *self baseline*: the same mean for the
//!   patches of 8 seeded square crops of the exemplar (side: half the exemplar's shorter side,
//!   rounded down), each matched against the exemplar patches that do not overlap its crop.
//!   1.0 means "as far from the exemplar as unseen parts of the exemplar are", 0 means every
//!   output patch is copied verbatim;
//! - `coverage`: the fraction of exemplar patch positions that are some scored output patch's
//!   nearest;
//! - `largest_offset`: the fraction of scored output patches whose nearest sits at the single
//!   most common offset (exemplar position minus output position); 1.0 means the output is one
//!   verbatim crop;
//! - `gradient_ratio`: the mean squared forward-difference gradient of the output over the
//!   exemplar's (below 1 = blurrier).
//!
//! The search is exhaustive and exact; ties go to the lowest exemplar index (`y · nx + x` over
//! the patch positions). The exemplar is stored as three channel planes, so that 16 adjacent
//! candidates of a row are compared with one query at once, one per SIMD lane (AVX2 when the
//! CPU has it, with bit-identical sums either way). Two prunings skip candidates without
//! changing the answer: a block of candidates is skipped when the per-channel sums rule all of
//! them out (`Σ_c (Σa_c − Σb_c)² / p² ≤ ‖a − b‖²`, with a margin so that a tie is never
//! pruned), and a block is abandoned once every lane's partial sum, accumulated row by row,
//! exceeds the best so far. The first candidate tried for a query is the previous query's
//! nearest shifted by the queries' displacement, which makes the bound tight at once on outputs
//! copied in pieces. Queries run in parallel (rayon); each query's answer depends only on the
//! query, so results are the same for any thread count.

use super::ImageView;
use crate::random::counter_hash;
use rayon::prelude::*;

/// Parameters of [`patch_score`].
#[derive(Clone, Copy, Debug)]
pub struct ScoreParams {
    /// Patch side in pixels.
    pub patch: u32,
    /// Most output patches scored (and most baseline patches); more are subsampled.
    pub max_queries: usize,
    /// Seed of the query subsets and of the baseline's crops.
    pub seed: u64,
}

impl Default for ScoreParams {
    fn default() -> Self {
        ScoreParams {
            patch: 7,
            max_queries: 20_000,
            seed: 0,
        }
    }
}

/// The measures; see the module docs. A ratio whose denominator is 0 is 1.0 when its
/// numerator is 0 too, and +∞ otherwise (which serde_json writes as `null`).
#[derive(Clone, Debug, serde::Serialize)]
pub struct PatchScore {
    /// `mean_rms / baseline_rms`.
    pub ratio: f64,
    /// Mean RMS distance of the scored output patches to their nearest exemplar patches.
    pub mean_rms: f64,
    /// Mean RMS distance of the baseline crops' patches to their nearest non-overlapping
    /// exemplar patches.
    pub baseline_rms: f64,
    pub coverage: f64,
    pub largest_offset: f64,
    pub gradient_ratio: f64,
    /// Output patches scored.
    pub queries: usize,
    /// Whether `queries` is a seeded subset of the output's patches.
    pub subsampled: bool,
}

/// Why two images cannot be scored.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ScoreError {
    #[error("patch size must be at least 1")]
    ZeroPatch,
    #[error("max_queries must be at least 1")]
    ZeroQueries,
    #[error("the mask has {len} flags for a {width}×{height} output")]
    MaskSize { width: u32, height: u32, len: usize },
    #[error("no {patch}×{patch} patch of the output lies wholly inside its mask")]
    NoPatchInMask { patch: u32 },
    #[error("{which} image is {width}×{height} but has {pixels} pixels")]
    PixelCount {
        which: &'static str,
        width: u32,
        height: u32,
        pixels: usize,
    },
    #[error("{which} image is {width}×{height}, smaller than the {patch}×{patch} patch")]
    TooSmall {
        which: &'static str,
        width: u32,
        height: u32,
        patch: u32,
    },
    #[error(
        "exemplar {width}×{height} is too small for any patch's verbatim layout under these \
         maps (the floor): each needs its patch plus a grid step of interpolation inside the \
         exemplar"
    )]
    FloorReach { width: u32, height: u32 },
    #[error(
        "exemplar {width}×{height} is too small for the self baseline with {patch}×{patch} \
         patches: its {crop}×{crop} crops (half its shorter side) need a whole patch inside \
         and one beside wherever they fall (a square exemplar needs at least {min_side}×{min_side})"
    )]
    BaselineTooSmall {
        width: u32,
        height: u32,
        patch: u32,
        crop: u32,
        min_side: u64,
    },
}

/// Indices `y · (w − patch + 1) + x` of the patch positions whose `patch × patch` pixels are
/// all inside `mask`, ascending (a summed-area table of the outside pixels).
fn patches_inside(mask: &[bool], w: usize, h: usize, patch: usize) -> Vec<usize> {
    let mut sat = vec![0u32; (w + 1) * (h + 1)];
    for y in 0..h {
        for x in 0..w {
            let out = u32::from(!mask[y * w + x]);
            sat[(y + 1) * (w + 1) + x + 1] =
                out + sat[y * (w + 1) + x + 1] + sat[(y + 1) * (w + 1) + x] - sat[y * (w + 1) + x];
        }
    }
    let (nx, ny) = (w - patch + 1, h - patch + 1);
    (0..nx * ny)
        .filter(|&i| {
            let (x, y) = (i % nx, i / nx);
            let at = |x: usize, y: usize| sat[y * (w + 1) + x];
            at(x + patch, y + patch) + at(x, y) - at(x + patch, y) - at(x, y + patch) == 0
        })
        .collect()
}

/// Square crops of the self baseline.
const BASELINE_CROPS: u64 = 8;
const STREAM_QUERIES: u64 = 1;
const STREAM_CROP_X: u64 = 2;
const STREAM_CROP_Y: u64 = 3;
const STREAM_BASELINE_QUERIES: u64 = 4;

/// Scores `output` against `exemplar`; see the module docs.
pub fn patch_score(
    output: ImageView<'_>,
    exemplar: ImageView<'_>,
    p: &ScoreParams,
) -> Result<PatchScore, ScoreError> {
    patch_score_masked(output, None, exemplar, p)
}

/// [`patch_score`] of the part of `output` where `mask` (one flag per pixel, row-major) is
/// set: only output patches wholly inside the mask are scored (the pool subsampling draws
/// from), and the output's gradient energy is the mean over neighbour pairs that are both
/// inside. For outputs that are pieces laid out on a canvas (atlas charts, resampled surface
/// patches) whose background must not count. `None` scores every pixel.
pub fn patch_score_masked(
    output: ImageView<'_>,
    mask: Option<&[bool]>,
    exemplar: ImageView<'_>,
    p: &ScoreParams,
) -> Result<PatchScore, ScoreError> {
    validate(Some(output), exemplar, p)?;
    let patch = p.patch as usize;
    let out = Plane::new(output);
    let ex = Plane::new(exemplar);

    // Output patches against the whole exemplar.
    let onx = out.w - patch + 1;
    let ony = out.h - patch + 1;
    let positions: Option<Vec<usize>> = match mask {
        None => None,
        Some(m) => {
            if m.len() != out.w * out.h {
                return Err(ScoreError::MaskSize {
                    width: output.width,
                    height: output.height,
                    len: m.len(),
                });
            }
            let inside = patches_inside(m, out.w, out.h, patch);
            if inside.is_empty() {
                return Err(ScoreError::NoPatchInMask { patch: p.patch });
            }
            Some(inside)
        }
    };
    let pool = positions.as_ref().map_or(onx * ony, |v| v.len());
    let cands = Candidates::new(&ex, patch);
    let (picked, subsampled) = subsample(pool, p.max_queries, p.seed, STREAM_QUERIES);
    let queries: Vec<Query> = picked
        .iter()
        .map(|&i| {
            let i = positions.as_ref().map_or(i, |v| v[i]);
            Query {
                x: i % onx,
                y: i / onx,
                crop: None,
            }
        })
        .collect();
    let found = cands.search(&out, &queries);
    let offsets: Vec<(i64, i64)> = queries
        .iter()
        .zip(&found)
        .map(|(q, &(idx, _))| {
            let (ex_x, ex_y) = (idx % cands.nx, idx / cands.nx);
            (ex_x as i64 - q.x as i64, ex_y as i64 - q.y as i64)
        })
        .collect();
    Ok(finish(
        &found,
        offsets,
        &cands,
        &ex,
        p,
        out.gradient_energy(mask),
        subsampled,
    ))
}

/// Output patches that were read from the output elsewhere (e.g. resampled along a map), to
/// be scored by [`patch_score_resampled`].
#[derive(Clone, Debug, Default)]
pub struct ResampledPatches {
    /// Side of each patch.
    pub patch: u32,
    /// The patches' RGB, `patch × patch` pixels each (row-major), one patch after another.
    pub rgb: Vec<[f32; 3]>,
    /// Per patch, where its top-left pixel sits in the output's frame, for `largest_offset`
    /// (the offset is the nearest exemplar position minus this).
    pub at: Vec<(i64, i64)>,
}

/// The seeded subset of `pool` output patches that [`patch_score_masked`] scores (all of them
/// when `pool ≤ max_queries`), ascending, and whether it is a subset: a caller resampling its
/// own patches picks the same ones.
pub fn query_subset(pool: usize, p: &ScoreParams) -> (Vec<usize>, bool) {
    subsample(pool, p.max_queries, p.seed, STREAM_QUERIES)
}

/// The measures of patches read by the caller: `patches` (the query subset already taken,
/// `subsampled` saying whether it is one) against `exemplar`, with the output's
/// `gradient_energy` (a [`GradientEnergy`] the caller accumulated the same way) over the
/// exemplar's. Equal to [`patch_score_masked`] when the patches, positions and energy are an
/// image's own.
pub fn patch_score_resampled(
    patches: &ResampledPatches,
    subsampled: bool,
    gradient_energy: f64,
    exemplar: ImageView<'_>,
    p: &ScoreParams,
) -> Result<PatchScore, ScoreError> {
    let patch = p.patch as usize;
    let n = patches.at.len();
    if patches.patch != p.patch || patches.rgb.len() != n * patch * patch {
        return Err(ScoreError::PixelCount {
            which: "resampled patches",
            width: patches.patch,
            height: n as u32,
            pixels: patches.rgb.len(),
        });
    }
    if n == 0 {
        return Err(ScoreError::NoPatchInMask { patch: p.patch });
    }
    // The output was checked through the patches above.
    validate(None, exemplar, p)?;
    let ex = Plane::new(exemplar);
    // The patches side by side in one strip, patch k at (k · patch, 0).
    let clamp = |c: f32| if c.is_nan() { 0.0 } else { c.clamp(0.0, 1.0) };
    let w = n * patch;
    let mut rgb = vec![0.0f32; 3 * w * patch];
    for k in 0..n {
        for y in 0..patch {
            for x in 0..patch {
                let px = patches.rgb[(k * patch + y) * patch + x];
                let o = 3 * (y * w + k * patch + x);
                for c in 0..3 {
                    rgb[o + c] = clamp(px[c]);
                }
            }
        }
    }
    let out = Plane { w, h: patch, rgb };
    let cands = Candidates::new(&ex, patch);
    let queries: Vec<Query> = (0..n)
        .map(|k| Query {
            x: k * patch,
            y: 0,
            crop: None,
        })
        .collect();
    let found = cands.search(&out, &queries);
    let offsets = patches
        .at
        .iter()
        .zip(&found)
        .map(|(&(ax, ay), &(idx, _))| {
            let (ex_x, ex_y) = (idx % cands.nx, idx / cands.nx);
            (ex_x as i64 - ax, ex_y as i64 - ay)
        })
        .collect();
    Ok(finish(
        &found,
        offsets,
        &cands,
        &ex,
        p,
        gradient_energy,
        subsampled,
    ))
}

/// The measures from the queries' nearest candidates `found` and their `offsets`.
fn finish(
    found: &[(usize, f32)],
    mut offsets: Vec<(i64, i64)>,
    cands: &Candidates,
    ex: &Plane,
    p: &ScoreParams,
    out_gradient: f64,
    subsampled: bool,
) -> PatchScore {
    let patch = p.patch as usize;
    let mean_rms = rms_mean(found, patch);

    let mut covered = vec![false; cands.nx * cands.ny];
    for &(idx, _) in found {
        covered[idx] = true;
    }
    let coverage = covered.iter().filter(|&&c| c).count() as f64 / covered.len() as f64;

    offsets.sort_unstable();
    let largest = offsets
        .chunk_by(|a, b| a == b)
        .map(|run| run.len())
        .max()
        .unwrap_or(0);
    let largest_offset = largest as f64 / found.len() as f64;

    // Self baseline: crops of the exemplar against the exemplar patches beside them.
    let side = ex.w.min(ex.h) / 2;
    let per_row = side - patch + 1;
    let per_crop = per_row * per_row;
    let crops: Vec<Crop> = (0..BASELINE_CROPS)
        .map(|k| Crop {
            x: (counter_hash(p.seed, STREAM_CROP_X, k) % (ex.w - side + 1) as u64) as usize,
            y: (counter_hash(p.seed, STREAM_CROP_Y, k) % (ex.h - side + 1) as u64) as usize,
            side,
        })
        .collect();
    let (picked, _) = subsample(
        crops.len() * per_crop,
        p.max_queries,
        p.seed,
        STREAM_BASELINE_QUERIES,
    );
    let baseline_queries: Vec<Query> = picked
        .iter()
        .map(|&i| {
            let crop = crops[i / per_crop];
            let j = i % per_crop;
            Query {
                x: crop.x + j % per_row,
                y: crop.y + j / per_row,
                crop: Some(crop),
            }
        })
        .collect();
    let baseline_rms = rms_mean(&cands.search(ex, &baseline_queries), patch);

    PatchScore {
        ratio: quotient(mean_rms, baseline_rms),
        mean_rms,
        baseline_rms,
        coverage,
        largest_offset,
        gradient_ratio: quotient(out_gradient, ex.gradient_energy(None)),
        queries: found.len(),
        subsampled,
    }
}

/// Checks the parameters and an exemplar as every score does (pixel count, room for a patch
/// and for the self baseline), for callers that read the exemplar before scoring against it.
pub fn validate_exemplar(exemplar: ImageView<'_>, p: &ScoreParams) -> Result<(), ScoreError> {
    validate(None, exemplar, p)
}

fn validate(
    output: Option<ImageView<'_>>,
    exemplar: ImageView<'_>,
    p: &ScoreParams,
) -> Result<(), ScoreError> {
    if p.patch == 0 {
        return Err(ScoreError::ZeroPatch);
    }
    if p.max_queries == 0 {
        return Err(ScoreError::ZeroQueries);
    }
    for (which, v) in [("output", output), ("exemplar", Some(exemplar))] {
        let Some(v) = v else { continue };
        if v.pixels.len() != v.width as usize * v.height as usize {
            return Err(ScoreError::PixelCount {
                which,
                width: v.width,
                height: v.height,
                pixels: v.pixels.len(),
            });
        }
        if v.width < p.patch || v.height < p.patch {
            return Err(ScoreError::TooSmall {
                which,
                width: v.width,
                height: v.height,
                patch: p.patch,
            });
        }
    }
    if !baseline_fits(exemplar.width, exemplar.height, p.patch) {
        return Err(ScoreError::BaselineTooSmall {
            width: exemplar.width,
            height: exemplar.height,
            patch: p.patch,
            crop: exemplar.width.min(exemplar.height) / 2,
            min_side: min_square_side(p.patch),
        });
    }
    Ok(())
}

/// Whether every baseline crop of a `w × h` exemplar holds a whole patch and leaves room for
/// one beside it, wherever the crop falls: the worst crop is centred, leaving
/// `ceil((w − side) / 2)` columns on its roomier side (likewise rows).
fn baseline_fits(w: u32, h: u32, patch: u32) -> bool {
    let side = w.min(h) / 2;
    side >= patch && (w - side).div_ceil(2).max((h - side).div_ceil(2)) >= patch
}

/// The least side of a square exemplar that [`baseline_fits`]: the crop side `n / 2` must be
/// at least `patch`, and so must the room `ceil(ceil(n / 2) / 2) = ceil(n / 4)`.
fn min_square_side(patch: u32) -> u64 {
    let patch = patch as u64;
    (2 * patch).max(4 * patch - 3)
}

/// `num / den`, 1.0 for 0 / 0 and +∞ for x / 0.
fn quotient(num: f64, den: f64) -> f64 {
    if den > 0.0 {
        num / den
    } else if num > 0.0 {
        f64::INFINITY
    } else {
        1.0
    }
}

/// Mean RMS distance of squared patch distances.
fn rms_mean(found: &[(usize, f32)], patch: usize) -> f64 {
    let values = (patch * patch * 3) as f64;
    let sum: f64 = found.iter().map(|&(_, d)| (d as f64 / values).sqrt()).sum();
    sum / found.len() as f64
}

/// The indices `0..n`, or when `n > max` the `max` of them with the smallest hashes of
/// (seed, stream, index), ascending; and whether it subsampled.
fn subsample(n: usize, max: usize, seed: u64, stream: u64) -> (Vec<usize>, bool) {
    if n <= max {
        return ((0..n).collect(), false);
    }
    // The `max` least (hash, index) pairs, in memory for `max` of them only.
    let mut kept = std::collections::BinaryHeap::with_capacity(max);
    for i in 0..n {
        let key = (counter_hash(seed, stream, i as u64), i);
        if kept.len() < max {
            kept.push(key);
        } else if key < *kept.peek().expect("max ≥ 1") {
            kept.pop();
            kept.push(key);
        }
    }
    let mut picked: Vec<usize> = kept.into_iter().map(|(_, i)| i).collect();
    picked.sort_unstable();
    (picked, true)
}

/// An image's RGB, clamped to [0, 1] (NaN read as 0), 3 floats a pixel, row-major.
struct Plane {
    w: usize,
    h: usize,
    rgb: Vec<f32>,
}

impl Plane {
    fn new(v: ImageView<'_>) -> Self {
        let clamp = |c: f32| if c.is_nan() { 0.0 } else { c.clamp(0.0, 1.0) };
        Plane {
            w: v.width as usize,
            h: v.height as usize,
            rgb: v
                .pixels
                .iter()
                .flat_map(|px| [clamp(px[0]), clamp(px[1]), clamp(px[2])])
                .collect(),
        }
    }

    /// The `patch` rows (`3 · patch` floats each) of the patch at `(x, y)`.
    #[inline]
    fn rows(&self, x: usize, y: usize, patch: usize) -> impl Iterator<Item = &[f32]> {
        let stride = 3 * self.w;
        let start = y * stride + 3 * x;
        (0..patch).map(move |r| &self.rgb[start + r * stride..start + r * stride + 3 * patch])
    }

    /// Mean over horizontal neighbour pairs of the squared RGB difference, plus the same over
    /// vertical pairs.
    fn gradient_energy(&self, mask: Option<&[bool]>) -> f64 {
        let (w, h) = (self.w, self.h);
        let inside = |x: usize, y: usize| mask.is_none_or(|m| m[y * w + x]);
        let px = |x: usize, y: usize| &self.rgb[3 * (y * w + x)..3 * (y * w + x) + 3];
        let mut g = GradientEnergy::default();
        for y in 0..h {
            for x in 0..w {
                if !inside(x, y) {
                    continue;
                }
                if x + 1 < w && inside(x + 1, y) {
                    g.add_x(px(x + 1, y), px(x, y));
                }
                if y + 1 < h && inside(x, y + 1) {
                    g.add_y(px(x, y + 1), px(x, y));
                }
            }
        }
        g.value()
    }
}

/// The gradient energy of [`PatchScore::gradient_ratio`], accumulated pair by pair: the mean
/// squared RGB difference over horizontal neighbour pairs plus the same over vertical pairs
/// (values clamped to [0, 1], NaN as 0, as the scored patches are). A caller that reads its
/// output's neighbours elsewhere (along a map) sums them here in the same order to get the
/// same bits.
#[derive(Clone, Copy, Debug, Default)]
pub struct GradientEnergy {
    gx: f64,
    nx: usize,
    gy: f64,
    ny: usize,
}

impl GradientEnergy {
    fn sq(a: &[f32], b: &[f32]) -> f64 {
        let clamp = |c: f32| if c.is_nan() { 0.0 } else { c.clamp(0.0, 1.0) };
        a.iter()
            .zip(b)
            .map(|(&a, &b)| {
                let d = (clamp(a) - clamp(b)) as f64;
                d * d
            })
            .sum()
    }

    /// A horizontal pair (`a` the right-hand pixel's RGB).
    pub fn add_x(&mut self, a: &[f32], b: &[f32]) {
        self.gx += Self::sq(a, b);
        self.nx += 1;
    }

    /// A vertical pair (`a` the lower pixel's RGB).
    pub fn add_y(&mut self, a: &[f32], b: &[f32]) {
        self.gy += Self::sq(a, b);
        self.ny += 1;
    }

    pub fn value(&self) -> f64 {
        let mean = |s: f64, n: usize| if n > 0 { s / n as f64 } else { 0.0 };
        mean(self.gx, self.nx) + mean(self.gy, self.ny)
    }
}

/// Per-channel sums of a patch given as rows of interleaved RGB, in f64.
fn channel_sums<'a>(rows: impl Iterator<Item = &'a [f32]>) -> [f64; 3] {
    let mut s = [0.0f64; 3];
    for row in rows {
        for px in row.chunks_exact(3) {
            for c in 0..3 {
                s[c] += px[c] as f64;
            }
        }
    }
    s
}

/// A square crop of the exemplar; patches that overlap it are not candidates.
#[derive(Clone, Copy, Debug)]
struct Crop {
    x: usize,
    y: usize,
    side: usize,
}

/// A patch to match: its top-left corner in its image, and the crop to keep away from.
#[derive(Clone, Copy, Debug)]
struct Query {
    x: usize,
    y: usize,
    crop: Option<Crop>,
}

/// Candidates compared at once: adjacent positions of one row, one per lane.
const LANES: usize = 16;

/// The exemplar's patch positions, searched exhaustively.
struct Candidates {
    patch: usize,
    nx: usize,
    ny: usize,
    /// The exemplar's R, G and B planes one after the other, each `h` rows of `stride` floats:
    /// the width, then zeros so that a block of [`LANES`] candidates reads in bounds.
    planes: Vec<f32>,
    stride: usize,
    plane_len: usize,
    /// Blocks per row: block `k` of row `y` holds the candidates `x = LANES·k ..` of that row,
    /// [`LANES`] of them (fewer in the last).
    blocks: usize,
    /// Per-channel (least, greatest) sum over each block's candidates, index `y · blocks + k`.
    block_sums: Vec<[(f64, f64); 3]>,
}

/// Queries a rayon task handles in order (each warm-starting from the one before).
const QUERY_CHUNK: usize = 32;

impl Candidates {
    fn new(ex: &Plane, patch: usize) -> Self {
        let nx = ex.w - patch + 1;
        let ny = ex.h - patch + 1;
        let stride = ex.w + LANES;
        let plane_len = stride * ex.h;
        let mut planes = vec![0.0; 3 * plane_len];
        for y in 0..ex.h {
            for x in 0..ex.w {
                for c in 0..3 {
                    planes[c * plane_len + y * stride + x] = ex.rgb[3 * (y * ex.w + x) + c];
                }
            }
        }
        let sums = (0..nx * ny)
            .into_par_iter()
            .map(|i| channel_sums(ex.rows(i % nx, i / nx, patch)))
            .collect::<Vec<_>>();
        let blocks = nx.div_ceil(LANES);
        let block_sums = (0..ny * blocks)
            .map(|b| {
                let (y, k) = (b / blocks, b % blocks);
                let first = y * nx + k * LANES;
                let last = y * nx + ((k + 1) * LANES).min(nx);
                let mut range = [(f64::INFINITY, f64::NEG_INFINITY); 3];
                for s in &sums[first..last] {
                    for c in 0..3 {
                        range[c] = (range[c].0.min(s[c]), range[c].1.max(s[c]));
                    }
                }
                range
            })
            .collect();
        Candidates {
            patch,
            nx,
            ny,
            planes,
            stride,
            plane_len,
            blocks,
            block_sums,
        }
    }

    /// The patch at `(x, y)` of `src` in the order the search reads it: by row, then by
    /// channel, then by column.
    fn query(&self, src: &Plane, x: usize, y: usize, out: &mut Vec<f32>) {
        out.clear();
        for row in src.rows(x, y, self.patch) {
            for c in 0..3 {
                out.extend(row.chunks_exact(3).map(|px| px[c]));
            }
        }
    }

    /// The nearest candidate (index, squared distance) of each query's patch in `src`.
    fn search(&self, src: &Plane, queries: &[Query]) -> Vec<(usize, f32)> {
        queries
            .par_chunks(QUERY_CHUNK)
            .flat_map_iter(|chunk| {
                let mut buf = Vec::with_capacity(self.patch * self.patch * 3);
                let mut prev: Option<(Query, usize)> = None;
                chunk
                    .iter()
                    .map(|&q| {
                        self.query(src, q.x, q.y, &mut buf);
                        let guess = prev.and_then(|(pq, best)| {
                            let gx = (best % self.nx + q.x).checked_sub(pq.x)?;
                            let gy = (best / self.nx + q.y).checked_sub(pq.y)?;
                            (gx < self.nx && gy < self.ny && !self.excluded(gx, gy, q.crop))
                                .then_some(gy * self.nx + gx)
                        });
                        let found = self.nearest(&buf, q.crop, guess);
                        prev = Some((q, found.0));
                        found
                    })
                    .collect::<Vec<_>>()
            })
            .collect()
    }

    /// Whether the candidate at `(x, y)` overlaps `crop`.
    #[inline]
    fn excluded(&self, x: usize, y: usize, crop: Option<Crop>) -> bool {
        crop.is_some_and(|c| {
            x < c.x + c.side && c.x < x + self.patch && y < c.y + c.side && c.y < y + self.patch
        })
    }

    /// Squared distances from `q` (see [`Candidates::query`]) to the candidates at
    /// `(x0 + j, y)` for each lane `j`, added to `init` (0 for a lane to compute, ∞ for one to
    /// skip); `None` once every lane's sum so far exceeds `bound`.
    ///
    /// Each lane sums in the same fixed order wherever the block starts (per row: each channel
    /// over the columns, then `(R + G) + B` added to the total), so a candidate's distance is
    /// the same in every block and every query, and with or without AVX2 (lane-wise adds and
    /// multiplies, never fused). Partial sums only grow (rounding is monotone and every term is
    /// non-negative), so `None` means every whole sum exceeds `bound`.
    #[inline(always)]
    fn block(
        &self,
        q: &[f32],
        x0: usize,
        y: usize,
        init: [f32; LANES],
        bound: f32,
    ) -> Option<[f32; LANES]> {
        let p = self.patch;
        let mut s = init;
        for (r, qr) in q.chunks_exact(3 * p).enumerate() {
            let row = (y + r) * self.stride + x0;
            let ex: [&[f32]; 3] =
                std::array::from_fn(|c| &self.planes[c * self.plane_len + row..][..p - 1 + LANES]);
            let qc: [&[f32]; 3] = std::array::from_fn(|c| &qr[c * p..][..p]);
            let mut acc = [[0.0f32; LANES]; 3];
            for i in 0..p {
                for c in 0..3 {
                    let qv = qc[c][i];
                    let src: &[f32; LANES] = ex[c][i..i + LANES].try_into().unwrap();
                    for j in 0..LANES {
                        let d = src[j] - qv;
                        acc[c][j] += d * d;
                    }
                }
            }
            let mut live = false;
            for j in 0..LANES {
                s[j] += (acc[0][j] + acc[1][j]) + acc[2][j];
                live |= s[j] <= bound;
            }
            if !live {
                return None;
            }
        }
        Some(s)
    }

    /// Squared distance from `q` to candidate `idx`, as [`Candidates::block`] computes it.
    #[inline(always)]
    fn distance(&self, q: &[f32], idx: usize) -> f32 {
        let mut init = [f32::INFINITY; LANES];
        init[0] = 0.0;
        let d = self.block(q, idx % self.nx, idx / self.nx, init, f32::INFINITY);
        d.expect("an infinite bound never stops a block")[0]
    }

    /// The exact nearest candidate not overlapping `crop` (lowest index among ties), trying
    /// `guess` first to tighten the bound. The same answer with and without AVX2.
    fn nearest(&self, q: &[f32], crop: Option<Crop>, guess: Option<usize>) -> (usize, f32) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked just above).
            return unsafe { self.nearest_avx2(q, crop, guess) };
        }
        self.nearest_portable(q, crop, guess)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn nearest_avx2(&self, q: &[f32], crop: Option<Crop>, guess: Option<usize>) -> (usize, f32) {
        self.nearest_portable(q, crop, guess)
    }

    /// [`Candidates::nearest`], compiled for whatever the caller is compiled for.
    #[inline(always)]
    fn nearest_portable(
        &self,
        q: &[f32],
        crop: Option<Crop>,
        guess: Option<usize>,
    ) -> (usize, f32) {
        let p = self.patch;
        let mut qsum = [0.0f64; 3];
        for qr in q.chunks_exact(3 * p) {
            for c in 0..3 {
                qsum[c] += qr[c * p..(c + 1) * p]
                    .iter()
                    .map(|&v| v as f64)
                    .sum::<f64>();
            }
        }
        let inv_pp = 1.0 / (p * p) as f64;
        let mut best = (usize::MAX, f32::INFINITY);
        if let Some(g) = guess {
            best = (g, self.distance(q, g));
        }
        for y in 0..self.ny {
            // Columns of this row whose candidates overlap the crop: [a, b).
            let (a, b) = match crop {
                Some(c) if y < c.y + c.side && c.y < y + p => (
                    (c.x + 1).saturating_sub(p).min(self.nx),
                    (c.x + c.side).min(self.nx),
                ),
                _ => (self.nx, self.nx),
            };
            for k in 0..self.blocks {
                let x0 = k * LANES;
                let n = (self.nx - x0).min(LANES);
                if a <= x0 && x0 + n <= b {
                    continue;
                }
                // Skip the block if its candidates' sums rule them all out. The computed
                // distance is within a relative 1e-5 of the exact one (at most 3·p²
                // non-negative f32 terms in short chains), so the margin never prunes a tie.
                let cut = best.1 as f64 * (1.0 + 1e-3) + 1e-12;
                let range = &self.block_sums[y * self.blocks + k];
                let mut lower = 0.0;
                for c in 0..3 {
                    let gap = (range[c].0 - qsum[c]).max(qsum[c] - range[c].1).max(0.0);
                    lower += gap * gap;
                }
                if lower * inv_pp > cut {
                    continue;
                }
                let first = y * self.nx + x0;
                let mut init = [f32::INFINITY; LANES];
                for j in 0..n {
                    if !(a..b).contains(&(x0 + j)) {
                        init[j] = 0.0;
                    }
                }
                if let Some(d) = self.block(q, x0, y, init, best.1) {
                    for j in 0..n {
                        let idx = first + j;
                        if init[j] == 0.0 && (d[j] < best.1 || (d[j] == best.1 && idx < best.0)) {
                            best = (idx, d[j]);
                        }
                    }
                }
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Image;
    use crate::math::PureMath;
    use crate::random::counter_unit;

    /// Smooth colour waves plus a little seeded noise, so no two patches are equal.
    fn structured(w: u32, h: u32, seed: u64) -> Image {
        Image::from_fn(w, h, |x, y| {
            let (xf, yf) = (x as f32, y as f32);
            let n = |c: u64| 0.1 * counter_unit(seed, c, (y * w + x) as u64);
            [
                0.45 + 0.35 * (0.5 * xf).sin_pure() * (0.3 * yf).cos_pure() + n(0),
                0.45 + 0.35 * (0.21 * xf + 0.4 * yf).sin_pure() + n(1),
                0.45 + 0.35 * (0.33 * yf).sin_pure() + n(2),
                1.0,
            ]
        })
    }

    fn noise(w: u32, h: u32, seed: u64) -> Image {
        Image::from_fn(w, h, |x, y| {
            let i = (y * w + x) as u64;
            [
                counter_unit(seed, 10, i),
                counter_unit(seed, 11, i),
                counter_unit(seed, 12, i),
                1.0,
            ]
        })
    }

    fn crop(img: &Image, x0: u32, y0: u32, w: u32, h: u32) -> Image {
        Image::from_fn(w, h, |x, y| img.view().get(x0 + x, y0 + y))
    }

    fn params() -> ScoreParams {
        ScoreParams::default()
    }

    #[test]
    fn verbatim_crop_scores_zero_and_one_offset() {
        let ex = structured(40, 40, 1);
        let out = crop(&ex, 6, 5, 28, 24);
        let s = patch_score(out.view(), ex.view(), &params()).unwrap();
        assert_eq!(s.mean_rms, 0.0, "{s:?}");
        assert_eq!(s.ratio, 0.0, "{s:?}");
        assert!(s.baseline_rms > 0.0, "{s:?}");
        assert_eq!(s.largest_offset, 1.0, "{s:?}");
        assert_eq!(s.queries, 22 * 18);
        assert!(!s.subsampled);
        // 22 × 18 of the 34 × 34 exemplar positions.
        assert!(
            (s.coverage - (22.0 * 18.0) / (34.0 * 34.0)).abs() < 1e-12,
            "{s:?}"
        );
    }

    #[test]
    fn four_quadrants_have_a_quarter_at_the_largest_offset() {
        let ex = structured(48, 48, 2);
        // (destination corner, source corner) of four 24 × 24 pieces, four distinct offsets.
        let pieces = [
            ((0, 0), (3, 1)),
            ((24, 0), (0, 20)),
            ((0, 24), (21, 0)),
            ((24, 24), (14, 9)),
        ];
        let out = Image::from_fn(48, 48, |x, y| {
            let &(d, s) = pieces
                .iter()
                .find(|((dx, dy), _)| x >= *dx && x < dx + 24 && y >= *dy && y < dy + 24)
                .unwrap();
            ex.view().get(s.0 + x - d.0, s.1 + y - d.1)
        });
        let s = patch_score(out.view(), ex.view(), &params()).unwrap();
        let total = 42.0 * 42.0;
        // At least a quadrant's inner patches, at most every patch overlapping the quadrant.
        let inner = 18.0 * 18.0 / total;
        let overlapping = 24.0 * 24.0 / total;
        assert!(
            s.largest_offset >= inner && s.largest_offset <= overlapping,
            "{inner} <= {} <= {overlapping}",
            s.largest_offset
        );
        assert!(s.mean_rms > 0.0 && s.ratio < 1.0, "{s:?}");
    }

    #[test]
    fn noise_is_far_from_a_structured_exemplar() {
        let ex = structured(40, 40, 3);
        let out = noise(24, 24, 4);
        let s = patch_score(out.view(), ex.view(), &params()).unwrap();
        assert!(s.ratio > 2.0, "{s:?}");
        assert!(s.gradient_ratio > 1.0, "{s:?}");
        assert!(s.largest_offset < 0.1, "{s:?}");
    }

    /// The exemplar's own pixels in a seeded random order: the same colours, none of the
    /// structure, so its patches are far from every exemplar patch.
    #[test]
    fn shuffled_pixels_are_far_from_the_exemplar() {
        let ex = structured(40, 40, 13);
        let mut order: Vec<(u64, usize)> = (0..ex.pixels.len())
            .map(|i| (crate::random::counter_hash(3, 0, i as u64), i))
            .collect();
        order.sort_unstable();
        let shuffled = Image::from_fn(40, 40, |x, y| ex.pixels[order[(y * 40 + x) as usize].1]);
        let s = patch_score(shuffled.view(), ex.view(), &params()).unwrap();
        // Twice as far as unseen parts of the exemplar (its noise keeps the baseline up).
        assert!(s.ratio > 2.0, "{s:?}");
        assert!(s.gradient_ratio > 5.0, "{s:?}");
        assert!(s.largest_offset < 0.05, "{s:?}");
    }

    /// A verbatim crop pasted on a noise canvas scores as the crop alone once the noise is
    /// masked out; unmasked, the noise makes it far from the exemplar.
    #[test]
    fn masked_canvas_scores_only_its_inside() {
        let ex = structured(40, 40, 14);
        let piece = crop(&ex, 9, 4, 20, 16);
        let bg = noise(48, 40, 15);
        let (ox, oy) = (13u32, 17u32);
        let inside = |x: u32, y: u32| x >= ox && x < ox + 20 && y >= oy && y < oy + 16;
        let canvas = Image::from_fn(48, 40, |x, y| {
            if inside(x, y) {
                piece.view().get(x - ox, y - oy)
            } else {
                bg.view().get(x, y)
            }
        });
        let mask: Vec<bool> = (0..48 * 40).map(|i| inside(i % 48, i / 48)).collect();
        let s = patch_score_masked(canvas.view(), Some(&mask), ex.view(), &params()).unwrap();
        let alone = patch_score(piece.view(), ex.view(), &params()).unwrap();
        assert_eq!(s.mean_rms, 0.0, "{s:?}");
        assert_eq!(s.largest_offset, 1.0, "{s:?}");
        assert_eq!(s.queries, 14 * 10);
        assert_eq!(s.coverage, alone.coverage);
        assert_eq!(s.gradient_ratio, alone.gradient_ratio);
        let unmasked = patch_score(canvas.view(), ex.view(), &params()).unwrap();
        assert!(unmasked.ratio > 1.0, "{unmasked:?}");
        // A mask holding no whole patch, and one of the wrong length, are errors.
        let thin: Vec<bool> = (0..48 * 40).map(|i| i % 48 < 6).collect();
        assert_eq!(
            patch_score_masked(canvas.view(), Some(&thin), ex.view(), &params()).unwrap_err(),
            ScoreError::NoPatchInMask { patch: 7 }
        );
        assert!(matches!(
            patch_score_masked(canvas.view(), Some(&mask[1..]), ex.view(), &params()),
            Err(ScoreError::MaskSize { .. })
        ));
    }

    /// The summed-area test against checking every pixel of every patch.
    #[test]
    fn patches_inside_the_mask_match_a_plain_check() {
        let (w, h, patch) = (23usize, 17usize, 4usize);
        let mask: Vec<bool> = (0..w * h)
            .map(|i| counter_unit(21, 0, i as u64) < 0.93)
            .collect();
        let nx = w - patch + 1;
        let want: Vec<usize> = (0..nx * (h - patch + 1))
            .filter(|&i| {
                let (x, y) = (i % nx, i / nx);
                (0..patch).all(|dy| (0..patch).all(|dx| mask[(y + dy) * w + x + dx]))
            })
            .collect();
        assert!(!want.is_empty() && want.len() < nx * (h - patch + 1));
        assert_eq!(patches_inside(&mask, w, h, patch), want);
    }

    #[test]
    fn blurred_copy_has_less_gradient_energy() {
        let ex = structured(40, 40, 5);
        let v = ex.view();
        let blurred = Image::from_fn(40, 40, |x, y| {
            let mut acc = [0.0f32; 4];
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let px = v.get_clamped(x as i64 + dx, y as i64 + dy);
                    for c in 0..4 {
                        acc[c] += px[c] / 9.0;
                    }
                }
            }
            acc
        });
        let s = patch_score(blurred.view(), ex.view(), &params()).unwrap();
        assert!(s.gradient_ratio < 0.8, "{s:?}");
        let same = patch_score(ex.view(), ex.view(), &params()).unwrap();
        assert!((same.gradient_ratio - 1.0).abs() < 1e-12, "{same:?}");
    }

    #[test]
    fn exemplar_against_itself_covers_everything() {
        let ex = structured(34, 30, 6);
        let s = patch_score(ex.view(), ex.view(), &params()).unwrap();
        assert_eq!(s.coverage, 1.0, "{s:?}");
        assert_eq!(s.mean_rms, 0.0);
        assert_eq!(s.largest_offset, 1.0);
        assert_eq!(s.queries, 28 * 24);
    }

    #[test]
    fn subsampling_is_seeded_and_reported() {
        let ex = structured(32, 32, 7);
        let out = noise(24, 24, 8);
        let p = ScoreParams {
            max_queries: 100,
            seed: 11,
            ..params()
        };
        let a = patch_score(out.view(), ex.view(), &p).unwrap();
        let b = patch_score(out.view(), ex.view(), &p).unwrap();
        assert!(a.subsampled && a.queries == 100, "{a:?}");
        assert_eq!(format!("{a:?}"), format!("{b:?}"));
        let c = patch_score(out.view(), ex.view(), &ScoreParams { seed: 12, ..p }).unwrap();
        assert_ne!(a.mean_rms, c.mean_rms);
        assert_ne!(a.baseline_rms, c.baseline_rms);
        let all = patch_score(out.view(), ex.view(), &params()).unwrap();
        assert!(!all.subsampled && all.queries == 18 * 18, "{all:?}");
    }

    #[test]
    fn thread_count_does_not_change_the_score() {
        let ex = structured(32, 32, 9);
        let out = noise(24, 24, 10);
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap()
            .install(|| patch_score(out.view(), ex.view(), &params()).unwrap());
        let many = rayon::ThreadPoolBuilder::new()
            .num_threads(3)
            .build()
            .unwrap()
            .install(|| patch_score(out.view(), ex.view(), &params()).unwrap());
        assert_eq!(format!("{one:?}"), format!("{many:?}"));
    }

    /// Two-level pixels: many patches are equal, so many distances tie exactly.
    fn two_level(w: u32, h: u32, seed: u64) -> Image {
        Image::from_fn(w, h, |x, y| {
            let v = if counter_unit(seed, 0, (y * w + x) as u64) < 0.8 {
                0.0
            } else {
                1.0
            };
            [v, v, 0.0, 1.0]
        })
    }

    /// The pruned, blocked search against a plain scan of every candidate, on exemplars full
    /// of exact ties and on smooth ones, with queries from other images and from the exemplar
    /// itself, with and without a crop to avoid.
    #[test]
    fn search_matches_brute_force() {
        let patch = 3;
        for ex_img in [
            two_level(41, 18, 1),
            structured(41, 18, 3),
            structured(20, 9, 4),
        ] {
            let ex = Plane::new(ex_img.view());
            let cands = Candidates::new(&ex, patch);
            let queries: Vec<Query> = (0..100)
                .map(|i| Query {
                    x: i % 10,
                    y: i / 10 % 6,
                    crop: (i % 3 == 0).then_some(Crop {
                        x: i % 11,
                        y: i % 5,
                        side: 5,
                    }),
                })
                .collect();
            let noisy = Plane::new(noise(12, 12, 5).view());
            let binary = Plane::new(two_level(12, 12, 6).view());
            for src in [&noisy, &binary, &ex] {
                let found = cands.search(src, &queries);
                let mut buf = Vec::new();
                for (q, &(idx, d)) in queries.iter().zip(&found) {
                    cands.query(src, q.x, q.y, &mut buf);
                    let mut want = (usize::MAX, f32::INFINITY);
                    for j in 0..cands.nx * cands.ny {
                        if cands.excluded(j % cands.nx, j / cands.nx, q.crop) {
                            continue;
                        }
                        let dj = cands.distance(&buf, j);
                        if dj < want.1 {
                            want = (j, dj);
                        }
                    }
                    assert_eq!((idx, d), want, "{q:?}");
                    // Without AVX2 (and without a first guess) too.
                    assert_eq!(cands.nearest_portable(&buf, q.crop, None), want, "{q:?}");
                }
            }
        }
    }

    #[test]
    fn distance_is_the_sum_of_squared_rgb_differences() {
        let ex = Plane::new(structured(30, 20, 1).view());
        let src = Plane::new(noise(10, 10, 2).view());
        let patch = 4;
        let cands = Candidates::new(&ex, patch);
        let mut buf = Vec::new();
        for (qx, qy, cx, cy) in [(0, 0, 0, 0), (6, 3, 26, 16), (2, 5, 17, 4)] {
            cands.query(&src, qx, qy, &mut buf);
            let mut want = 0.0f64;
            for r in 0..patch {
                for i in 0..patch {
                    for c in 0..3 {
                        let a = src.rgb[3 * ((qy + r) * src.w + qx + i) + c] as f64;
                        let b = ex.rgb[3 * ((cy + r) * ex.w + cx + i) + c] as f64;
                        want += (a - b) * (a - b);
                    }
                }
            }
            let got = cands.distance(&buf, cy * cands.nx + cx) as f64;
            assert!((got - want).abs() < 1e-5 * want, "{got} {want}");
        }
    }

    #[test]
    fn small_images_are_errors() {
        let ex = structured(32, 32, 1);
        let tiny = structured(6, 30, 1);
        assert_eq!(
            patch_score(tiny.view(), ex.view(), &params()).unwrap_err(),
            ScoreError::TooSmall {
                which: "output",
                width: 6,
                height: 30,
                patch: 7
            }
        );
        assert!(matches!(
            patch_score(ex.view(), tiny.view(), &params()),
            Err(ScoreError::TooSmall {
                which: "exemplar",
                ..
            })
        ));
        let small = structured(24, 24, 1);
        let err = patch_score(ex.view(), small.view(), &params()).unwrap_err();
        assert_eq!(
            err,
            ScoreError::BaselineTooSmall {
                width: 24,
                height: 24,
                patch: 7,
                crop: 12,
                min_side: 25
            }
        );
        assert!(err.to_string().contains("24×24"), "{err}");
        let enough = structured(25, 25, 1);
        assert!(patch_score(ex.view(), enough.view(), &params()).is_ok());
        for patch in 1..40 {
            let n = min_square_side(patch) as u32;
            assert!(baseline_fits(n, n, patch) && !baseline_fits(n - 1, n - 1, patch));
        }
        let zero = ScoreParams {
            patch: 0,
            ..params()
        };
        assert_eq!(
            patch_score(ex.view(), ex.view(), &zero).unwrap_err(),
            ScoreError::ZeroPatch
        );
    }
}
