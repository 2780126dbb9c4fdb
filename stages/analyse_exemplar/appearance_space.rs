//! A sample's appearance space, prepared for parallel synthesis of exemplar coordinates.
//!
//! Implements the exemplar side of S. Lefebvre and H. Hoppe, "Appearance-space texture
//! synthesis" (SIGGRAPH 2006) §3 (the appearance-space transform: each texel's 5×5 neighbourhood
//! reduced by PCA to a short appearance vector) on the Gaussian stack of S. Lefebvre and
//! H. Hoppe, "Parallel controllable texture synthesis" (SIGGRAPH 2005) §3.1, with the
//! k-coherence candidate sets of X. Tong et al. 2002 that their correction step (§3.2) draws
//! from. Per stack level `ℓ` (spacing `h = 2^ℓ` finest texels):
//! - the stack level: level `ℓ − 1` blurred by the 5-tap binomial with its taps `2^(ℓ−1)`
//!   texels apart (à trous), borders clamped (samples are not assumed to tile);
//! - appearance vectors: the 5×5 taps `h` apart around each texel (mirrored at the borders),
//!   channels weighted by the variants' channel weights, reduced by PCA to
//!   [`APPEARANCE_DIMS`];
//! - neighbourhood vectors: the 3×3 appearance vectors `h` apart around each texel
//!   ([`NEIGHBOURHOOD_DIMS`] numbers), which synthesis compares;
//! - k-coherence sets: per texel, itself followed by the `k − 1` texels whose neighbourhood
//!   vectors are nearest, among those at least `2h` texels away in either axis and at least
//!   `h` inside the borders ([`interior_margin`]): synthesis steers coordinates into that
//!   interior, so a coherent run that reaches a border restarts instead of repeating the
//!   border texel into a streak.
//!
//! Departures: the paper builds its appearance vectors from the finest exemplar and a stack of
//! them; here each level has its own basis, fitted to that level's (coarser, more blurred)
//! neighbourhoods, as its Gaussian stack matches at that level. The candidate sets are searched
//! in the first [`SEARCH_DIMS`] principal components of the neighbourhood vectors (a shortlist
//! of `4k`, found approximately: [`SEARCH_EPS`]), then ranked by the full vectors. Every level is analysed, whatever level synthesis
//! starts at, so the cached space serves any field and density.

use crate::geom::geometry_image::TexelImage;
use crate::image::knn::{KdTree, KdTreeRef, squared_distance};
use crate::image::neighbourhood::mirror;
use crate::image::pca::{Pca, PcaParams};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Length of an appearance vector.
pub const APPEARANCE_DIMS: usize = 8;
/// Length of a neighbourhood vector: 3×3 appearance vectors.
pub const NEIGHBOURHOOD_DIMS: usize = 9 * APPEARANCE_DIMS;
/// Principal components of the neighbourhood vectors the candidate search runs in.
pub const SEARCH_DIMS: usize = 8;
/// The shortlist search is approximate (Arya & Mount): its i-th point is within `1 + eps` of
/// the true i-th nearest distance. The shortlist is ranked by the full vectors anyway, and
/// with exact search the node took 174 s for a 512² sample against 27 s (BENCHMARKS.md,
/// "Appearance analysis of large samples").
pub const SEARCH_EPS: f32 = 1.0;
/// At most this many vectors (a regular subsample) fit each PCA basis.
const PCA_FIT_SAMPLES: usize = 16384;

/// The `appearance_space` node's algorithm and version (part of its key; bump on any change of
/// output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("appearance_space", 4);

/// The sizes of an appearance space: the sample's, its channels, its stack levels and the
/// entries of each k-coherence set.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct AppearanceMeta {
    pub width: u32,
    pub height: u32,
    pub channels: u32,
    pub levels: u32,
    pub k: u32,
}

impl AppearanceMeta {
    fn texels(&self) -> usize {
        self.width as usize * self.height as usize
    }
}

/// A sample's appearance space, one block per stack level `ℓ` (spacing `2^ℓ`) in each array:
/// the Gaussian stack (unweighted texels, row by row), the neighbourhood vectors
/// ([`NEIGHBOURHOOD_DIMS`] per texel) and the k-coherence sets (`k` texel indices per texel,
/// the texel itself first).
pub struct AppearanceSpace {
    pub meta: AppearanceMeta,
    pub stack: Vec<f32>,
    pub neighbourhoods: Vec<f32>,
    pub candidates: Vec<u32>,
}

/// An appearance space as a reader sees it (borrowed, e.g. from a memory-mapped artifact).
#[derive(Clone, Copy, Debug)]
pub struct AppearanceSpaceRef<'a> {
    pub meta: AppearanceMeta,
    pub stack: &'a [f32],
    pub neighbourhoods: &'a [f32],
    pub candidates: &'a [u32],
}

/// One stack level of an appearance space, borrowed.
#[derive(Clone, Copy, Debug)]
pub struct AppearanceLevel<'a> {
    /// Tap spacing in finest texels, `2^ℓ`.
    pub spacing: u32,
    /// The stack level's texels (unweighted).
    pub texels: &'a [f32],
    /// Per texel, its neighbourhood vector.
    pub neighbourhoods: &'a [f32],
    /// Per texel, its k-coherence set.
    pub candidates: &'a [u32],
}

impl<'a> AppearanceSpaceRef<'a> {
    /// Checks that the arrays hold what `meta` says: sizes within a sample's (8 to
    /// [`MAX_SIDE`] texels a side), lengths that match, candidates inside the sample and
    /// finite numbers.
    pub fn new(
        meta: AppearanceMeta,
        stack: &'a [f32],
        neighbourhoods: &'a [f32],
        candidates: &'a [u32],
    ) -> Result<Self, String> {
        let bad = |why: &str| Err(format!("appearance space {meta:?}: {why}"));
        let side = 8..=MAX_SIDE;
        if !side.contains(&meta.width) || !side.contains(&meta.height) {
            return bad("sample size out of range");
        }
        if !(1..=8).contains(&meta.k) || !(1..=16).contains(&meta.levels) {
            return bad("k or levels out of range");
        }
        if !(1..=6).contains(&meta.channels) {
            return bad("channels out of range");
        }
        let (n, l) = (meta.texels(), meta.levels as usize);
        let len = |per: usize| l.checked_mul(n).and_then(|ln| ln.checked_mul(per));
        if Some(stack.len()) != len(meta.channels as usize)
            || Some(neighbourhoods.len()) != len(NEIGHBOURHOOD_DIMS)
            || Some(candidates.len()) != len(meta.k as usize)
        {
            return bad("array lengths disagree with the sizes");
        }
        if candidates.iter().any(|&u| u as usize >= n) {
            return bad("a candidate lies outside the sample");
        }
        if !stack.iter().chain(neighbourhoods).all(|v| v.is_finite()) {
            return bad("a value is not finite");
        }
        Ok(AppearanceSpaceRef {
            meta,
            stack,
            neighbourhoods,
            candidates,
        })
    }

    /// Stack level `l`.
    pub fn level(&self, l: usize) -> AppearanceLevel<'a> {
        let n = self.meta.texels();
        let (c, k) = (self.meta.channels as usize, self.meta.k as usize);
        AppearanceLevel {
            spacing: 1 << l,
            texels: &self.stack[l * n * c..(l + 1) * n * c],
            neighbourhoods: &self.neighbourhoods
                [l * n * NEIGHBOURHOOD_DIMS..(l + 1) * n * NEIGHBOURHOOD_DIMS],
            candidates: &self.candidates[l * n * k..(l + 1) * n * k],
        }
    }
}

/// The largest sample side an appearance space holds (coordinates stay exact in `f32`).
pub const MAX_SIDE: u32 = 1 << 14;

/// The stack levels a sample of `w × h` gets: the coarsest spacing `h` is the largest power of
/// two with `4 h ≤ min(w, h)`, so it lies between an eighth and a quarter of the shorter side.
/// The coarsest level's neighbourhood (5×5 appearance taps around 3×3 neighbourhood taps,
/// `± 3 h`) then spans 0.75 to 1.5 times the shorter side: synthesis starts from a level that
/// sees the sample's largest structures whole and places them as whole runs before finer levels
/// fill them in (BENCHMARKS.md, "Appearance synthesis: a deeper stack"). Every tap is at most
/// `2 h ≤ min / 2` from its texel, which one mirroring keeps inside.
pub fn stack_levels(w: u32, h: u32) -> usize {
    let mut levels = 1;
    while (1u32 << levels) * 4 <= w.min(h) {
        levels += 1;
    }
    levels
}

impl AppearanceSpace {
    /// The appearance space of `sample` ([`stack_levels`] levels), channels weighted by
    /// `weights`, k-coherence sets of `k` (at least 1).
    pub fn build(sample: &TexelImage, weights: &[f32], k: usize) -> Self {
        let (w, h) = (sample.width as usize, sample.height as usize);
        let c = sample.channels as usize;
        let k = k.max(1);
        let levels = stack_levels(sample.width, sample.height);
        let mut stack: Vec<Vec<f32>> = vec![sample.data.clone()];
        for l in 1..levels {
            stack.push(blur_dilated(&stack[l - 1], w, h, c, 1i64 << (l - 1)));
        }
        let mut neighbourhoods = Vec::with_capacity(levels * w * h * NEIGHBOURHOOD_DIMS);
        let mut candidates = Vec::with_capacity(levels * w * h * k);
        for (l, texels) in stack.iter().enumerate() {
            let weighted: Vec<f32> = texels
                .chunks_exact(c)
                .flat_map(|t| t.iter().zip(weights).map(|(v, wt)| v * wt))
                .collect();
            let spacing = 1i64 << l;
            let appearance = appearance_vectors(&weighted, w, h, c, spacing);
            let neigh = neighbourhood_vectors(&appearance, w, h, spacing);
            candidates.extend(coherence_sets(&neigh, w, h, spacing, k));
            neighbourhoods.extend(neigh);
        }
        AppearanceSpace {
            meta: AppearanceMeta {
                width: w as u32,
                height: h as u32,
                channels: c as u32,
                levels: levels as u32,
                k: k as u32,
            },
            stack: stack.concat(),
            neighbourhoods,
            candidates,
        }
    }

    pub fn view(&self) -> AppearanceSpaceRef<'_> {
        AppearanceSpaceRef {
            meta: self.meta,
            stack: &self.stack,
            neighbourhoods: &self.neighbourhoods,
            candidates: &self.candidates,
        }
    }
}

/// The analysis node: the appearance space of the variants' middle scale, orientation 0 (the
/// sample's central square at its own texel size; resampled half a texel off, so slightly
/// blurred, when the sides differ by an odd number), with the variants' channel weights.
pub fn node(
    variants: &crate::analyse_exemplar::texel_variants::TexelVariantsRef<'_>,
    k: u32,
) -> Result<AppearanceSpace, texsyn_core::algorithm::Failure> {
    let sample = base_sample(variants);
    check_sides(sample.width, sample.height).map_err(texsyn_core::algorithm::Failure::input)?;
    if (1..=8).contains(&k) {
        Ok(AppearanceSpace::build(
            &sample,
            &variants.meta.channel_weights,
            k as usize,
        ))
    } else {
        Err(texsyn_core::algorithm::Failure::input(format!(
            "synthesize.appearance_k must be 1 to 8, got {k}"
        )))
    }
}

/// Whether a `w × h` sample fits the appearance synthesizer, which analyses its central
/// square: 8 to [`MAX_SIDE`] texels on the shorter side.
pub fn check_sides(w: u32, h: u32) -> Result<(), String> {
    if (8..=MAX_SIDE).contains(&w.min(h)) {
        Ok(())
    } else {
        Err(format!(
            "{w}×{h} texels, but the appearance synthesizer needs 8 to {MAX_SIDE} texels on the \
             shorter side"
        ))
    }
}

/// The variants' middle scale, orientation 0, finest level: the sample's central square at its
/// own texel size.
pub fn base_sample(
    variants: &crate::analyse_exemplar::texel_variants::TexelVariantsRef<'_>,
) -> TexelImage {
    let base = variants.level(variants.variant(variants.params().middle_scale(), 0), 0);
    TexelImage {
        width: base.width,
        height: base.height,
        channels: variants.channels() as u32,
        data: base.texels.to_vec(),
    }
}

/// The binomial 1-4-6-4-1 blur along rows then columns with taps `step` texels apart, borders
/// clamped.
fn blur_dilated(src: &[f32], w: usize, h: usize, c: usize, step: i64) -> Vec<f32> {
    const TAPS: [f32; 5] = [1.0 / 16.0, 4.0 / 16.0, 6.0 / 16.0, 4.0 / 16.0, 1.0 / 16.0];
    let pass = |src: &[f32], along_x: bool| -> Vec<f32> {
        let mut dst = vec![0.0f32; src.len()];
        dst.par_chunks_mut(w * c).enumerate().for_each(|(y, row)| {
            for x in 0..w {
                for (t, &wt) in TAPS.iter().enumerate() {
                    let d = (t as i64 - 2) * step;
                    let (sx, sy) = if along_x {
                        ((x as i64 + d).clamp(0, w as i64 - 1) as usize, y)
                    } else {
                        (x, (y as i64 + d).clamp(0, h as i64 - 1) as usize)
                    };
                    let s = (sy * w + sx) * c;
                    for ch in 0..c {
                        row[x * c + ch] += wt * src[s + ch];
                    }
                }
            }
        });
        dst
    };
    pass(&pass(src, true), false)
}

/// At most [`PCA_FIT_SAMPLES`] of the `dim`-vectors in `data`: all of them, or vector
/// `i · p mod n` for `i < PCA_FIT_SAMPLES` with `p` a prime near `n / PCA_FIT_SAMPLES · φ` not
/// dividing `n`, which spreads over every column (a plain stride dividing the width would fit
/// the basis to a few columns, one phase of a periodic sample).
fn fit_subsample(data: &[f32], dim: usize) -> Vec<f32> {
    let n = data.len() / dim;
    if n <= PCA_FIT_SAMPLES {
        return data.to_vec();
    }
    let is_prime = |p: usize| {
        p >= 2
            && (2..)
                .take_while(|d| d * d <= p)
                .all(|d| !p.is_multiple_of(d))
    };
    let mut p = (n as f64 / PCA_FIT_SAMPLES as f64 * 1.618_034) as usize + 1;
    while !is_prime(p) || n.is_multiple_of(p) {
        p += 1;
    }
    (0..PCA_FIT_SAMPLES)
        .flat_map(|i| {
            let v = (i * p) % n;
            data[v * dim..(v + 1) * dim].iter().copied()
        })
        .collect()
}

fn pca_of(data: &[f32], dim: usize, components: usize) -> Pca {
    let params = PcaParams {
        components: components as u32,
        ..Default::default()
    };
    Pca::fit(&fit_subsample(data, dim), dim, &params)
}

/// Each texel's 5×5 neighbourhood, taps `step` apart (mirrored at the borders), reduced to
/// [`APPEARANCE_DIMS`] by PCA.
fn appearance_vectors(stack: &[f32], w: usize, h: usize, c: usize, step: i64) -> Vec<f32> {
    let dim = 25 * c;
    let mut raw = vec![0.0f32; w * h * dim];
    raw.par_chunks_mut(dim).enumerate().for_each(|(t, v)| {
        let (x, y) = ((t % w) as i64, (t / w) as i64);
        let mut o = 0;
        for dy in -2..=2i64 {
            for dx in -2..=2i64 {
                let sx = mirror(x + dx * step, w as i64) as usize;
                let sy = mirror(y + dy * step, h as i64) as usize;
                let s = (sy * w + sx) * c;
                v[o..o + c].copy_from_slice(&stack[s..s + c]);
                o += c;
            }
        }
    });
    let pca = pca_of(&raw, dim, APPEARANCE_DIMS);
    let mut out = pca.project_all(&raw);
    // Fewer components than asked (a sample with few channels): pad with zeros.
    let got = pca.components();
    if got < APPEARANCE_DIMS {
        out = out
            .chunks_exact(got.max(1))
            .flat_map(|a| {
                let mut v = [0.0f32; APPEARANCE_DIMS];
                v[..got].copy_from_slice(&a[..got]);
                v
            })
            .collect();
        if got == 0 {
            out = vec![0.0; w * h * APPEARANCE_DIMS];
        }
    }
    out
}

/// The 3×3 appearance vectors `step` apart around each texel (mirrored at the borders).
fn neighbourhood_vectors(appearance: &[f32], w: usize, h: usize, step: i64) -> Vec<f32> {
    let mut out = vec![0.0f32; w * h * NEIGHBOURHOOD_DIMS];
    out.par_chunks_mut(NEIGHBOURHOOD_DIMS)
        .enumerate()
        .for_each(|(t, v)| {
            let (x, y) = ((t % w) as i64, (t / w) as i64);
            for (o, (dx, dy)) in TAPS_3X3.iter().enumerate() {
                let sx = mirror(x + dx * step, w as i64) as usize;
                let sy = mirror(y + dy * step, h as i64) as usize;
                let s = (sy * w + sx) * APPEARANCE_DIMS;
                v[o * APPEARANCE_DIMS..(o + 1) * APPEARANCE_DIMS]
                    .copy_from_slice(&appearance[s..s + APPEARANCE_DIMS]);
            }
        });
    out
}

/// The margin, in texels, of the interior a level's candidates come from: the spacing `h` of
/// its 3×3 taps (so the 3×3 taps stay inside; the outer two rings of the appearance vectors'
/// 5×5 taps may still be mirrored), at most a quarter of the smaller side.
pub fn interior_margin(w: u32, h: u32, spacing: u32) -> u32 {
    spacing.min(w.min(h) / 4)
}

/// The 3×3 taps in row order, `(dx, dy)`.
pub const TAPS_3X3: [(i64, i64); 9] = [
    (-1, -1),
    (0, -1),
    (1, -1),
    (-1, 0),
    (0, 0),
    (1, 0),
    (-1, 1),
    (0, 1),
    (1, 1),
];

/// Per texel, itself and the `k − 1` texels of the interior ([`interior_margin`]; at least
/// `2 step` away in x or y) with the nearest neighbourhood vectors: a shortlist of `4k` from
/// the first [`SEARCH_DIMS`] components (within [`SEARCH_EPS`]), ranked by the full vectors
/// (ties by index).
///
/// The search skips the kd-tree's subtrees whose texels all lie within the gap (at coarse
/// levels a texel's nearest neighbourhoods are mostly its spatial neighbours, which used to be
/// measured one by one), and starts from the left neighbour's shortlist moved one texel.
///
/// At the coarsest level the interior can be as narrow as `2 step` (a side of `4 step`), and
/// then a texel inside it has no far candidate and its set is itself `k` times: correction
/// there only chooses among the coordinates its neighbours' runs propose, which lays the
/// largest structures out as whole runs. Shrinking the gap to fit the interior would give
/// every texel candidates, and measured worse on a stretched sheet (BENCHMARKS.md).
fn coherence_sets(neigh: &[f32], w: usize, h: usize, step: i64, k: usize) -> Vec<u32> {
    let n = w * h;
    if k == 1 {
        return (0..n as u32).collect();
    }
    let pca = pca_of(neigh, NEIGHBOURHOOD_DIMS, SEARCH_DIMS);
    let dims = pca.components().max(1);
    let reduced = if pca.components() == 0 {
        vec![0.0; n]
    } else {
        pca.project_all(neigh)
    };
    let m = interior_margin(w as u32, h as u32, step as u32) as i64;
    let (xs, ys) = (m..w as i64 - m, m..h as i64 - m);
    let gap = 2 * step;
    // Only interior texels are candidates, so only they enter the tree (in increasing index,
    // so that ties still go to the smaller texel index).
    let interior: Vec<u32> = (0..n as u32)
        .filter(|&u| {
            let (ux, uy) = ((u as usize % w) as i64, (u as usize / w) as i64);
            xs.contains(&ux) && ys.contains(&uy)
        })
        .collect();
    let points: Vec<f32> = interior
        .iter()
        .flat_map(|&u| &reduced[u as usize * dims..(u as usize + 1) * dims])
        .copied()
        .collect();
    let tree = KdTree::build(&points, dims);
    let tree = tree.as_ref();
    let boxes = node_boxes(&tree, |i| {
        let u = interior[i as usize] as usize;
        ((u % w) as i64, (u / w) as i64)
    });
    let iw = xs.end - xs.start;
    let mut out = vec![0u32; n * k];
    // Rows in parallel, each row from left to right: a texel's search starts from its left
    // neighbour's results moved one texel right (the sets of neighbouring texels are mostly
    // each other's shifted), which gives it a tight bound at once. An approximate search's
    // results depend on the seeds (an exact one's would not), so they are made in this order
    // whatever the thread count, and a change to the seeding changes the node's output.
    out.par_chunks_mut(w * k).enumerate().for_each(|(y, row)| {
        let y = y as i64;
        let mut found: Vec<(u32, f32)> = Vec::new();
        let mut seeds: Vec<(u32, f32)> = Vec::new();
        for (x, set) in row.chunks_exact_mut(k).enumerate() {
            let x = x as i64;
            let t = (y * w as i64 + x) as usize;
            let far = |i: u32| {
                let u = interior[i as usize] as usize;
                let (ux, uy) = ((u % w) as i64, (u / w) as i64);
                (ux - x).abs() >= gap || (uy - y).abs() >= gap
            };
            // A subtree whose texels all lie within the gap holds no candidate.
            let near = |node: u32| {
                let b = &boxes[node as usize];
                b.x.0 > x - gap && b.x.1 < x + gap && b.y.0 > y - gap && b.y.1 < y + gap
            };
            let q = &reduced[t * dims..(t + 1) * dims];
            seeds.clear();
            seeds.extend(found.iter().filter_map(|&(i, _)| {
                let next = (i as i64 % iw + 1 < iw).then_some(i + 1)?;
                let p = next as usize * dims;
                Some((next, squared_distance(q, &points[p..p + dims])))
            }));
            found = if far_candidate_exists(x, y, &xs, &ys, gap) {
                tree.nearest_approx_seeded(q, 4 * k, SEARCH_EPS, far, near, &seeds)
            } else {
                // The search would visit every texel to find none.
                Vec::new()
            };
            let me = &neigh[t * NEIGHBOURHOOD_DIMS..(t + 1) * NEIGHBOURHOOD_DIMS];
            let mut ranked: Vec<(f32, u32)> = found
                .iter()
                .map(|&(i, _)| {
                    let u = interior[i as usize];
                    let u0 = u as usize * NEIGHBOURHOOD_DIMS;
                    (squared_distance(me, &neigh[u0..u0 + NEIGHBOURHOOD_DIMS]), u)
                })
                .collect();
            ranked.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            set[0] = t as u32;
            for (s, slot) in set[1..].iter_mut().enumerate() {
                // Too few far texels (a tiny sample): repeat the texel itself.
                *slot = ranked.get(s).map_or(t as u32, |r| r.1);
            }
        }
    });
    out
}

/// The range of texel columns `x` and rows `y` under a kd-tree node.
struct NodeBox {
    x: (i64, i64),
    y: (i64, i64),
}

/// Per node of `tree`, the bounding box of the texel positions `at(point index)` under it.
fn node_boxes(tree: &KdTreeRef<'_>, at: impl Fn(u32) -> (i64, i64)) -> Vec<NodeBox> {
    let (nodes, ids) = (tree.nodes(), tree.ids());
    let mut boxes: Vec<NodeBox> = (0..nodes.len())
        .map(|_| NodeBox {
            x: (i64::MAX, i64::MIN),
            y: (i64::MAX, i64::MIN),
        })
        .collect();
    // Children come after their parent, so a reverse walk has both before it reaches it.
    for (i, nd) in nodes.iter().enumerate().rev() {
        let mut b = NodeBox {
            x: (i64::MAX, i64::MIN),
            y: (i64::MAX, i64::MIN),
        };
        let mut add = |x: i64, y: i64| {
            b.x = (b.x.0.min(x), b.x.1.max(x));
            b.y = (b.y.0.min(y), b.y.1.max(y));
        };
        if nd.axis == u32::MAX {
            for &id in &ids[nd.start as usize..nd.end as usize] {
                let (x, y) = at(id);
                add(x, y);
            }
        } else {
            for c in [nd.left, nd.right] {
                let cb = &boxes[c as usize];
                add(cb.x.0, cb.y.0);
                add(cb.x.1, cb.y.1);
            }
        }
        boxes[i] = b;
    }
    boxes
}

/// Whether some texel of the interior `xs × ys` lies at least `gap` from `(x, y)` in x or in y.
fn far_candidate_exists(
    x: i64,
    y: i64,
    xs: &std::ops::Range<i64>,
    ys: &std::ops::Range<i64>,
    gap: i64,
) -> bool {
    let reaches = |r: &std::ops::Range<i64>, c: i64| c - gap >= r.start || c + gap < r.end;
    !xs.is_empty() && !ys.is_empty() && (reaches(xs, x) || reaches(ys, y))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_view_refuses_sizes_that_overflow_or_disagree_and_values_that_are_not_finite() {
        let space = AppearanceSpace::build(&stripes(16, 16, 4), &[1.0, 1.0, 1.0], 2);
        let v = space.view();
        let ok = |m: AppearanceMeta, s: &[f32], nb: &[f32], c: &[u32]| {
            AppearanceSpaceRef::new(m, s, nb, c).is_ok()
        };
        assert!(ok(v.meta, v.stack, v.neighbourhoods, v.candidates));
        // Sizes whose products wrap to the empty arrays' lengths.
        let huge = AppearanceMeta {
            width: 1 << 31,
            height: 1 << 31,
            ..v.meta
        };
        assert!(!ok(huge, &[], &[], &[]));
        let wider = AppearanceMeta {
            width: 17,
            ..v.meta
        };
        assert!(!ok(wider, v.stack, v.neighbourhoods, v.candidates));
        let mut c = v.candidates.to_vec();
        c[5] = 16 * 16;
        assert!(!ok(v.meta, v.stack, v.neighbourhoods, &c));
        let mut s = v.stack.to_vec();
        s[3] = f32::NAN;
        assert!(!ok(v.meta, &s, v.neighbourhoods, v.candidates));
    }

    #[test]
    fn the_pca_subsample_visits_every_column() {
        // 256² vectors of one number, the column index: a stride of 4 (what 65536 / 16384
        // gives) would only ever see columns 0, 4, 8, ….
        let data: Vec<f32> = (0..256 * 256).map(|t| (t % 256) as f32).collect();
        let sub = fit_subsample(&data, 1);
        assert_eq!(sub.len(), PCA_FIT_SAMPLES);
        let mut seen = [false; 256];
        for v in sub {
            seen[v as usize] = true;
        }
        assert!(seen.iter().all(|&s| s), "columns missed");
    }

    fn stripes(w: u32, h: u32, period: u32) -> TexelImage {
        let mut s = TexelImage::new(w, h, 3);
        for y in 0..h {
            for x in 0..w {
                s.texel_mut(x, y)[2] = if (x / (period / 2)).is_multiple_of(2) {
                    1.0
                } else {
                    0.0
                };
            }
        }
        s
    }

    #[test]
    fn candidates_of_vertical_stripes_share_the_phase_and_keep_their_distance() {
        let s = stripes(48, 48, 8);
        let space = AppearanceSpace::build(&s, &[1.0, 1.0, 1.0], 4);
        let view = space.view();
        let lv = view.level(0);
        for y in (6..42).step_by(5) {
            for x in (6..42).step_by(5) {
                let t = y * 48 + x;
                let set = &lv.candidates[t * 4..t * 4 + 4];
                assert_eq!(set[0], t as u32, "the texel itself first");
                for &u in &set[1..] {
                    let (ux, uy) = (u as usize % 48, u as usize / 48);
                    let far = ux.abs_diff(x) >= 2 || uy.abs_diff(y) >= 2;
                    assert!(far, "candidate {ux},{uy} of {x},{y} is too close");
                    // Away from the borders, the best matches sit at the same stripe phase.
                    if (6..42).contains(&ux) && (6..42).contains(&uy) {
                        assert_eq!(ux % 8, x % 8, "candidate {ux},{uy} of {x},{y}");
                    }
                }
            }
        }
    }

    #[test]
    fn a_far_candidate_exists_exactly_where_a_scan_finds_one() {
        for (w, h, gap, margin) in [(64i64, 64i64, 32, 16), (40, 24, 8, 4), (16, 16, 8, 8)] {
            let (xs, ys) = (margin..w - margin, margin..h - margin);
            for y in 0..h {
                for x in 0..w {
                    let scan = ys.clone().any(|uy| {
                        xs.clone()
                            .any(|ux| (ux - x).abs() >= gap || (uy - y).abs() >= gap)
                    });
                    assert_eq!(far_candidate_exists(x, y, &xs, &ys, gap), scan, "{x},{y}");
                }
            }
        }
    }

    #[test]
    fn the_coarsest_spacing_is_between_an_eighth_and_a_quarter_of_the_shorter_side() {
        for (w, h) in [
            (8, 8),
            (9, 300),
            (64, 64),
            (127, 200),
            (128, 128),
            (300, 257),
        ] {
            let coarsest = 1u32 << (stack_levels(w, h) - 1);
            let side = w.min(h);
            assert!(
                4 * coarsest <= side && side < 8 * coarsest,
                "{w}×{h}: {coarsest}"
            );
        }
    }

    #[test]
    fn coarser_levels_are_blurred_and_their_taps_spread() {
        let s = stripes(64, 64, 4);
        let space = AppearanceSpace::build(&s, &[1.0, 1.0, 1.0], 2);
        let view = space.view();
        // The coarsest spacing is a quarter of the side.
        assert_eq!(space.meta.levels, 5);
        assert_eq!(view.level(4).spacing, 16);
        assert_eq!(view.level(2).spacing, 4);
        // Period-4 stripes vanish from level 2 on (a blur across 2 periods): its
        // neighbourhoods nearly agree away from the borders, level 0's do not.
        let spread = |lv: AppearanceLevel| {
            let a = &lv.neighbourhoods[(32 * 64 + 30) * NEIGHBOURHOOD_DIMS..][..NEIGHBOURHOOD_DIMS];
            let b = &lv.neighbourhoods[(32 * 64 + 32) * NEIGHBOURHOOD_DIMS..][..NEIGHBOURHOOD_DIMS];
            squared_distance(a, b)
        };
        assert!(spread(view.level(0)) > 100.0 * spread(view.level(2)));
    }
}
