//! Texture optimization on a surface with the feature-to-feature constraint: Xu et al.,
//! "Feature-Aligned Shape Texturing" (2009), §5.1–5.2, built on the texture optimization of
//! Kwatra, Essa, Bobick & Kwatra, "Texture optimization for example-based synthesis"
//! (SIGGRAPH 2005) in its surface form (Kwatra et al. 2007, "Texture fluids", which runs it on
//! the points of a surface).
//!
//! The energy (§5.1, eq. 3) is `E = Σ_{p ∈ X†} λ_p ω_p |x_p − z_p|²` over a subset X† of the
//! vertices: `x_p` are the colours of the vertices around sample `p` (its "grid patch",
//! expressed at the vertices as in texture fluids), `z_p` the exemplar patch that matches them
//! best, `ω_p = |x_p − z_p|^(r−2)` Kwatra's robust weight (r = `robust_exponent`, 0.8), so that
//! each sample contributes `λ_p |x_p − z_p|^r`. The minimization alternates
//!
//! - a nearest-neighbour search (Kwatra's "E-step"): the sample's patch, resampled onto a
//!   regular `w × w` grid in its tangent frame, is matched against every exemplar patch of the
//!   same grid laid along `exemplar_angle` (PCA-reduced vectors in a kd-tree, the few nearest
//!   re-ranked by the full distance);
//! - a least-squares solve ("M-step"): the energy is a sum of squares per vertex once ω is
//!   fixed, so every vertex's colour is the `λ_p ω_p`-weighted mean of what the patches that
//!   cover it say it should be: `E(z_p + R·(s_qp, t_qp))`, the exemplar bilinearly looked up at
//!   the vertex's exact offset `(s, t)` in the sample's frame, rotated onto the exemplar.
//!
//! A vertex `q`'s offset in sample `p`'s patch is `((q − p)·u_p, (q − p)·v_p) / texel_size` with
//! `u_p` the field projected into `p`'s tangent plane and `v_p = n_p × u_p`; the patch holds
//! the vertices found by a breadth-first walk over edges from `p` that stay within a Euclidean
//! distance `(w/2)·√2` texels of `p` (so the walk follows the surface and does not jump across
//! thin gaps) and whose offsets satisfy `|s|, |t| ≤ w/2`.
//!
//! The samples X† (§5.1, after Chen et al. 2009) are picked greedily in a priority order: a
//! vertex becomes a sample unless an earlier sample lies within `r·w` texels of it (r =
//! `sample_spacing`). With feature curves, the order is vertices on the curves first, then by
//! increasing curve distance while within `w/2` of a curve, then the rest in random order; so
//! the curves are sampled every `r·w` first, then their surroundings, as the paper describes.
//!
//! §5.2's constraint: a sample at curve distance `d(p) < w/2` texels may only match exemplar
//! patches whose centre lies at a distance from the texture's feature lines within
//! `feature_tolerance` texels of `d(p)` — the kd-tree's filtered query. If no exemplar patch
//! passes, the sample searches unconstrained and is counted in `unconstrained_fallbacks`.
//!
//! Choices where the papers leave values open, and departures:
//! - **λ_p (eq. 4)**: the paper's `1/(d + 10⁻⁶)` gives samples on a curve a million times the
//!   weight of a sample one unit away, so along a curve nothing but the on-curve samples
//!   contributes, and the weight's size depends on the model's units. Here `d` is in texels and
//!   `λ_p = 1 / clamp(d, min_curve_distance, w/2)`: the same 1/d law in the band where the
//!   constraint acts, capped at `1/min_curve_distance` (default 1 texel: an on-curve sample
//!   weighs as much as one a texel away and w/2 times one outside the band; 0.25 gave a 4%
//!   worse nearest-patch score in the benchmark), and constant outside the band,
//!   where the paper's 1/d would only tilt weights between neighbouring samples for no purpose.
//!   `min_curve_distance = 1e-6` is the paper's literal law inside the band. Without features,
//!   λ = 1 (§5.1).
//! - **ω_p** floors `|x_p − z_p|` at 10⁻⁴ (a perfect match would otherwise weigh infinitely);
//!   `|x_p − z_p|²` is the sum of squared RGB differences over the patch's vertices, and the
//!   reported `final_energy` is `Σ λ_p |x_p − z_p|^r` after the last least-squares step.
//! - **Grid patch at the vertices**: the patch's vertices are splatted bilinearly onto the
//!   matching grid (each cell: the tent-weighted mean of the vertices within one cell of it),
//!   and the exemplar patches are sampled with the same tent (bilinear at the finest level, a
//!   tent `2^l` texels wide at coarse levels, so a one-texel line is seen wherever it lies, not
//!   only on every other texel). On a texel-aligned grid with the field along an axis this is
//!   exactly the vertex colours. A cell no vertex reaches (mesh boundary, a back-facing fold, a
//!   mesh coarser than a texel) is left out of the distance: the tree query fills it with the
//!   current match's values, the re-ranking skips it and considers 16 instead of 4 tree
//!   candidates. Vertices whose normal faces away from the sample's (`n_q · n_p ≤ 0`) are not in
//!   its patch.
//! - **Exemplar borders**: exemplars are not assumed tileable, so candidate centres are the
//!   pixel centres whose whole rotated patch (the square `|s|,|t| ≤ w/2`, rotated by
//!   `exemplar_angle`) lies inside the exemplar; lookups never wrap. Odd `w` puts the grid
//!   cells on pixel centres when the angle is a multiple of 90°, so matching compares exact
//!   pixels; other angles interpolate bilinearly.
//! - **Search**: PCA to `components` dimensions, fitted to 256 evenly spread candidates through
//!   their Gram matrix with a block power iteration (`crate::image::pca::Pca::fit`'s Jacobi
//!   solver is cubic in the dimension `w²·3`, up to 12 288: 0.9 s per level at w = 15), then an
//!   approximate kd-tree query (Arya–Mount, `search_eps`) for the 4 nearest (16 with the
//!   occurrence penalty, which needs alternatives to choose from), re-ranked by the
//!   full `w²·3`-dimensional distance together with the current match (so a sample's match
//!   never gets worse by its own measure and the iteration can settle).
//! - **Multi-resolution** (Kwatra 2005 §4 runs coarse to fine; Xu et al. §6 ask for it for
//!   speed): `levels` runs of the whole optimization, the coarsest first; level `l` below the
//!   finest uses patches `2^l·w` texels wide whose grid has a `2^l`-texel step (the same `w×w`
//!   vector size; tent-filtered on both sides, see above), with samples `r·2^l·w` apart. The
//!   coarse level lays out the large structures (a line's course over 2w texels), the fine level
//!   repairs the detail: with one level the striped test's nearest-patch ratio is 3.4–5.3, with
//!   two 1.3–2.8. A coarse level is skipped when its candidate centres would cover less than
//!   half of either exemplar side (too few to choose from); the finest must fit
//!   (`ExemplarTooSmall`). The M-step always looks up the sharp exemplar at the vertices' exact
//!   offsets. A level starts each sample's match (which fills its empty grid cells) at the
//!   exemplar position its vertex got at the previous level; the first level starts from random
//!   positions.
//! - **Occurrence penalty** (not in Xu et al. nor Kwatra et al.; Kopf et al. 2007, "Solid
//!   texture synthesis from 2D exemplars", §3.3): plain texture optimization settles on the
//!   exemplar's most common content. On brick it drops every mortar line: each 15-texel window
//!   inside a brick matches itself perfectly, so an all-brick result has a low energy (seen on
//!   fandisk and on a flat sheet; `the_occurrence_penalty_keeps_rare_features` measures it).
//!   Exemplar positions are counted in 8×8-texel blocks over the current matches; a candidate
//!   in a block used more than its fair share (its candidates × samples / candidates) gets
//!   `penalty = 1 + histogram · (use/fair − 1)`. It multiplies the candidate's distance in the
//!   search (Kopf re-weights only the solve; in the search it also steers new matches away
//!   from over-used content, which the solve's weights alone did not do in the tests) and
//!   divides the sample's ω in the colour solve, as Kopf does. `histogram = 0` is plain texture
//!   optimization.
//! - **Iteration**: E then M, `iterations` times per level, stopping early when no sample's match
//!   changed. Initially every vertex takes the colour its nearest sample's random patch gives
//!   it (pieces of exemplar pasted side by side), not the mean of the random patches: the
//!   mean is a grey blur from which the first search finds no structure to lock on to.
//! - Vertices no patch covers (only possible with `sample_spacing > 0.5`, whose spacing exceeds
//!   the patch half-width) take the colour and source of the nearest covered vertex in edge
//!   hops, and are counted. Vertices used by no triangle get the exemplar's mean colour and the
//!   source `[-1, -1]`.
//! - The field is projected into each vertex's tangent plane; where it vanishes there, an
//!   arbitrary tangent direction is used.
//!
//! [`curve_distance`] gives the per-vertex geodesic distance the constraint needs: Dijkstra
//! whose updates also cross triangles (fast marching's planar-front update from the two
//! finished corners of a triangle), exact from a straight curve on a flat mesh, where edge
//! Dijkstra follows the edges' zigzag; see its doc for the measured error.

use crate::check::{ParamError, check_range};
use crate::geom::Mesh;
use crate::graph::{Csr, Dijkstra};
use crate::image::Image;
use crate::image::knn::{KdTree, squared_distance};
use crate::image::pca::{Pca, symmetric_eigen};
use crate::random::counter_hash;
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;
use texsyn_core::math::PureMath;

/// The `texture_optimization` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("texture_optimization", 1);

const STREAM_ORDER: u64 = 1;
const STREAM_INIT: u64 = 2;
/// Candidate patches the PCA basis is fitted to (evenly spread over the candidates).
const PCA_FIT_VECTORS: usize = 256;
/// Nearest candidates in PCA space re-ranked by the full distance; more for samples whose grid
/// has empty cells (their query is partly the current match, which biases the tree search).
const SEARCH_K: usize = 4;
const SEARCH_K_PARTIAL: usize = 16;
/// Block power iterations of the PCA fit.
const POWER_ITERATIONS: usize = 30;
/// Floor of `|x_p − z_p|` in Kwatra's weight.
const MIN_PATCH_DISTANCE: f32 = 1e-4;

/// Parameters of [`texture_optimization`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TextureOptimizationParams {
    /// Patch side `w` in exemplar texels at the finest level, 4..=64. Default: 15 — odd, so the
    /// matching grid sits on pixel centres (see the module doc); 15 spans a stripe or a
    /// brick row of a typical 64–128 px exemplar, and with the default two levels the coarse
    /// level sees 30 texels, Kwatra's large-patch pass.
    pub patch: u32,
    /// The paper's `r`: samples are at most `r·w` texels apart, 0.05..=1. Default: 0.25
    /// (the paper's value; each vertex is then covered by about 16 patches). Above 0.5 some
    /// vertices may be covered by no patch.
    pub sample_spacing: f32,
    /// Kwatra's robust exponent `r` in `ω_p = |x_p − z_p|^(r−2)`, 0.1..=2 (2 = plain least
    /// squares). Default: 0.8 (Kwatra 2005 §3.1).
    pub robust_exponent: f32,
    /// Search/solve iterations per level, 1..=100; a level stops earlier when no match
    /// changes. Default: 10 (the striped test's score still improved from 6 to 10).
    pub iterations: u32,
    /// §5.2's threshold: a constrained sample matches only exemplar patches whose centre's
    /// feature distance differs from the sample's curve distance by at most this, in texels,
    /// 0..=64. Default: 0.75: a window 1.5 texels wide holds a texel-centre distance for any
    /// curve distance, and samples on a curve (d = 0) may only take patches centred on a line
    /// (with a tolerance of 1 or more they settled one texel beside a one-texel line in the
    /// tests).
    pub feature_tolerance: f32,
    /// Seed of the sampling order and the initial matches. Default: 0.
    pub seed: u64,
    /// Resolution levels, 1..=3; level `l` (counted from the finest) matches patches `2^l·w`
    /// texels wide on a `2^l`-texel grid. Default: 2.
    pub levels: u32,
    /// PCA dimensions of the search, 4..=64. Default: 24.
    pub components: u32,
    /// Approximation of the kd-tree search, 0..=10 (0 = exact in PCA space; results are within
    /// `1 + eps` of the nearest distance). Default: 1.
    pub search_eps: f32,
    /// Smallest curve distance in texels used in `λ_p = 1/d`, 1e-6..=64 (see the module doc:
    /// it caps the weight of on-curve samples). Default: 1: on-curve samples weigh as much as
    /// samples a texel away. Chosen by the benchmark's quality row (a 192² sheet, one curve,
    /// brick.png, mean of 3 seeds): nearest-patch ratio 1.065× the unconstrained one at 1,
    /// 1.106× at 0.25, 1.094× at 0.75/1.5 tolerance; the constraint itself is unchanged.
    pub min_curve_distance: f32,
    /// Weight of the occurrence penalty (Kopf et al. 2007, "Solid texture synthesis from 2D
    /// exemplars", §3.3), 0..=10; 0 is plain texture optimization. Default: 1 (see the
    /// module doc: without it the optimization settles on the exemplar's most common content
    /// and drops its rarer features, the mortar of a brick wall).
    pub histogram: f32,
}

impl Default for TextureOptimizationParams {
    fn default() -> Self {
        TextureOptimizationParams {
            patch: 15,
            sample_spacing: 0.25,
            robust_exponent: 0.8,
            iterations: 10,
            feature_tolerance: 0.75,
            seed: 0,
            levels: 2,
            components: 24,
            search_eps: 1.0,
            min_curve_distance: 1.0,
            histogram: 1.0,
        }
    }
}

impl TextureOptimizationParams {
    /// Checks every field's range; the error names the key, its range and the value.
    pub fn validate(&self) -> Result<(), ParamError> {
        check_range("synthesize.patch", self.patch, 4, 64)?;
        check_range("synthesize.sample_spacing", self.sample_spacing, 0.05, 1.0)?;
        check_range("synthesize.robust_exponent", self.robust_exponent, 0.1, 2.0)?;
        check_range("synthesize.iterations", self.iterations, 1, 100)?;
        check_range(
            "synthesize.feature_tolerance",
            self.feature_tolerance,
            0.0,
            64.0,
        )?;
        check_range("synthesize.levels", self.levels, 1, 3)?;
        check_range("synthesize.components", self.components, 4, 64)?;
        check_range("synthesize.search_eps", self.search_eps, 0.0, 10.0)?;
        check_range(
            "synthesize.min_curve_distance",
            self.min_curve_distance,
            1e-6,
            64.0,
        )?;
        check_range("synthesize.histogram", self.histogram, 0.0, 10.0)
    }
}

/// What [`texture_optimization`] synthesizes on.
pub struct SurfaceSynthesisInput<'a> {
    /// Refined so that edges are about one exemplar texel long or shorter.
    pub mesh: &'a Mesh,
    /// Per vertex, the direction the exemplar's `exemplar_angle` direction is laid along
    /// (projected into the tangent plane here; need not be unit).
    pub field: &'a [Vec3],
    pub exemplar: &'a Image,
    /// Object units per exemplar texel.
    pub texel_size: f32,
    /// Radians: the direction in exemplar pixel coordinates (x right, y down) that the field
    /// maps onto.
    pub exemplar_angle: f32,
    /// None: unconstrained synthesis (the paper's Fig. 7 middle column).
    pub features: Option<FeatureConstraint<'a>>,
}

/// §5.2's inputs.
pub struct FeatureConstraint<'a> {
    /// Per vertex: geodesic distance to the shape's feature curves, object units (∞ or NaN:
    /// far from every curve).
    pub curve_distance: &'a [f32],
    /// Per exemplar texel, row-major: distance to the texture's feature lines, texels.
    pub texture_distance: &'a [f32],
}

/// The synthesized texture.
#[derive(Clone, Debug)]
pub struct SurfaceSynthesis {
    /// Per vertex RGB, in the exemplar's encoding.
    pub colours: Vec<[f32; 3]>,
    /// Per vertex: the exemplar texel address (pixel centres at integers, x right, y down) its
    /// colour came from, taken from the covering patch of largest weight; `[-1, -1]` for
    /// vertices used by no triangle.
    pub source: Vec<[f32; 2]>,
    pub stats: SynthesisStats,
}

/// Counters of a run (of its finest level where per level).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SynthesisStats {
    /// Samples (|X†|) at the finest level.
    pub samples: u32,
    /// Iterations run, summed over the levels.
    pub iterations_run: u32,
    /// Finest-level samples within `w/2` of a curve (searched under the constraint).
    pub constrained_samples: u32,
    /// Of those, samples for which no exemplar patch satisfied the constraint.
    pub unconstrained_fallbacks: u32,
    /// `Σ λ_p |x_p − z_p|^r` after the last least-squares step.
    pub final_energy: f64,
    /// Referenced vertices covered by no patch (filled from the nearest covered vertex).
    pub uncovered_vertices: u32,
    /// Levels run (coarse levels whose patch does not fit the exemplar are skipped).
    pub levels_run: u32,
}

/// Why [`texture_optimization`] cannot run.
#[derive(Debug, thiserror::Error)]
pub enum SynthesisError {
    #[error(
        "synthesize.patch = {patch} texels does not fit in the {width}×{height} exemplar: rotated \
         by exemplar_angle {angle_degrees:.1}° the patch needs {needed}×{needed} texels; lower \
         synthesize.patch or use a larger exemplar"
    )]
    ExemplarTooSmall {
        patch: u32,
        width: u32,
        height: u32,
        needed: u32,
        angle_degrees: f32,
    },
    #[error("texture optimization input mismatch: {0}")]
    InputMismatch(String),
    #[error(transparent)]
    Params(#[from] ParamError),
}

/// λ_p of a sample at curve distance `d` texels (see the module doc). `d` not below `band`
/// (NaN and ∞ included) is outside the constraint's reach.
fn curve_weight(d: f32, band: f32, floor: f32) -> f32 {
    let d = if d < band { d.max(floor) } else { band };
    1.0 / d
}

/// Exemplar RGB with bilinear lookups.
struct Rgb {
    w: usize,
    h: usize,
    px: Vec<[f32; 3]>,
}

impl Rgb {
    #[inline]
    fn sample(&self, p: Vec2) -> [f32; 3] {
        let x = p.x.clamp(0.0, (self.w - 1) as f32);
        let y = p.y.clamp(0.0, (self.h - 1) as f32);
        let x0 = (x as usize).min(self.w - 1);
        let y0 = (y as usize).min(self.h - 1);
        let x1 = (x0 + 1).min(self.w - 1);
        let y1 = (y0 + 1).min(self.h - 1);
        let fx = x - x0 as f32;
        let fy = y - y0 as f32;
        let a = self.px[y0 * self.w + x0];
        let b = self.px[y0 * self.w + x1];
        let c = self.px[y1 * self.w + x0];
        let d = self.px[y1 * self.w + x1];
        let mut out = [0.0; 3];
        for k in 0..3 {
            let top = a[k] + (b[k] - a[k]) * fx;
            let bot = c[k] + (d[k] - c[k]) * fx;
            out[k] = top + (bot - top) * fy;
        }
        out
    }
}

impl Rgb {
    /// The exemplar filtered with a tent of half-width `width` texels at `p` (`width` 1 is
    /// the bilinear lookup): what a grid of that step sees without aliasing.
    fn tent(&self, p: Vec2, width: f32) -> [f32; 3] {
        if width <= 1.0 {
            return self.sample(p);
        }
        let mut acc = [0.0f32; 3];
        let mut wsum = 0.0f32;
        let (x0, x1) = ((p.x - width).ceil() as i64, (p.x + width).floor() as i64);
        let (y0, y1) = ((p.y - width).ceil() as i64, (p.y + width).floor() as i64);
        for y in y0..=y1 {
            let wy = 1.0 - (y as f32 - p.y).abs() / width;
            if wy <= 0.0 {
                continue;
            }
            let yy = y.clamp(0, self.h as i64 - 1) as usize;
            for x in x0..=x1 {
                let wx = 1.0 - (x as f32 - p.x).abs() / width;
                if wx <= 0.0 {
                    continue;
                }
                let xx = x.clamp(0, self.w as i64 - 1) as usize;
                let c = self.px[yy * self.w + xx];
                let wgt = wx * wy;
                for k in 0..3 {
                    acc[k] += wgt * c[k];
                }
                wsum += wgt;
            }
        }
        acc.map(|a| a / wsum)
    }
}

/// Rotation of local `(s, t)` onto exemplar pixel axes.
#[derive(Clone, Copy)]
struct Rot {
    c: f32,
    s: f32,
}

impl Rot {
    #[inline]
    fn apply(&self, o: [f32; 2]) -> Vec2 {
        Vec2::new(o[0] * self.c - o[1] * self.s, o[0] * self.s + o[1] * self.c)
    }
}

/// One resolution level.
#[derive(Clone, Copy)]
struct Level {
    /// Grid cells per side.
    w: usize,
    /// Texels per grid cell.
    step: f32,
}

impl Level {
    /// Patch side in texels.
    fn extent(&self) -> f32 {
        self.w as f32 * self.step
    }
    fn dim(&self) -> usize {
        self.w * self.w * 3
    }
    /// Offset in texels of grid cell `a` along one axis.
    #[inline]
    fn cell_offset(&self, a: usize) -> f32 {
        (a as f32 - (self.w as f32 - 1.0) * 0.5) * self.step
    }
}

/// The exemplar patches of one level: every candidate centre's grid vector, its PCA
/// projection in a kd-tree, and its feature distance.
struct Candidates {
    /// First candidate centre's x and y (the margin).
    margin: usize,
    nx: usize,
    full: Vec<f32>,
    pca: Pca,
    tree: KdTree,
    /// Feature distance at each candidate centre; sorted copy for existence checks.
    distance: Option<(Vec<f32>, Vec<f32>)>,
}

impl Candidates {
    fn len(&self) -> usize {
        self.full.len() / self.pca.dim
    }
    #[inline]
    fn centre(&self, i: u32) -> Vec2 {
        let i = i as usize;
        Vec2::new(
            (self.margin + i % self.nx) as f32,
            (self.margin + i / self.nx) as f32,
        )
    }
    /// The candidate nearest to exemplar address `p`, clamped into the candidate rectangle.
    fn nearest_to(&self, p: [f32; 2]) -> u32 {
        let ny = self.len() / self.nx;
        let clamp = |v: f32, n: usize| {
            let v = (v.round() - self.margin as f32).clamp(0.0, (n - 1) as f32);
            if v.is_nan() { 0 } else { v as usize }
        };
        (clamp(p[1], ny) * self.nx + clamp(p[0], self.nx)) as u32
    }
    /// Whether some candidate's feature distance is within `tol` of `d`.
    fn any_within(&self, d: f32, tol: f32) -> bool {
        let Some((_, sorted)) = &self.distance else {
            return true;
        };
        let i = sorted.partition_point(|&x| x < d - tol);
        i < sorted.len() && sorted[i] <= d + tol
    }
}

/// Half-width in texels the rotated patch square reaches along the exemplar axes, rounded up to
/// whole pixels.
fn margin(level: Level, rot: Rot) -> usize {
    let half = level.extent() * 0.5 * (rot.c.abs() + rot.s.abs());
    (half - 1e-3).ceil().max(0.0) as usize
}

fn build_candidates(
    ex: &Rgb,
    texture_distance: Option<&[f32]>,
    level: Level,
    rot: Rot,
    components: usize,
) -> Option<Candidates> {
    let m = margin(level, rot);
    if ex.w < 2 * m + 1 || ex.h < 2 * m + 1 {
        return None;
    }
    let nx = ex.w - 2 * m;
    let ny = ex.h - 2 * m;
    // A coarse level with candidates over less than half of each side has too few to choose
    // from (a 60-texel patch in a 64-texel exemplar has 16) and only scrambles the layout.
    if level.step > 1.0 && (2 * nx < ex.w || 2 * ny < ex.h) {
        return None;
    }
    let dim = level.dim();
    let offsets: Vec<Vec2> = (0..level.w * level.w)
        .map(|c| {
            rot.apply([
                level.cell_offset(c % level.w),
                level.cell_offset(c / level.w),
            ])
        })
        .collect();
    let mut full = vec![0.0f32; nx * ny * dim];
    full.par_chunks_mut(dim).enumerate().for_each(|(i, out)| {
        let centre = Vec2::new((m + i % nx) as f32, (m + i / nx) as f32);
        for (c, o) in offsets.iter().enumerate() {
            out[c * 3..c * 3 + 3].copy_from_slice(&ex.tent(centre + *o, level.step));
        }
    });
    let pca = fit_pca(&full, dim, components);
    let proj = pca.project_all(&full);
    let tree = KdTree::build(&proj, pca.components());
    let distance = texture_distance.map(|td| {
        let d: Vec<f32> = (0..nx * ny)
            .map(|i| td[(m + i / nx) * ex.w + m + i % nx])
            .collect();
        let mut sorted: Vec<f32> = d.iter().copied().filter(|x| !x.is_nan()).collect();
        sorted.sort_by(f32::total_cmp);
        (d, sorted)
    });
    Some(Candidates {
        margin: m,
        nx,
        full,
        pca,
        tree,
        distance,
    })
}

/// PCA of the rows of `data`, fitted to at most [`PCA_FIT_VECTORS`] evenly spread rows through
/// their Gram matrix `G = X Xᵀ`: the principal directions of that subset are `Xᵀu/√λ` for the
/// eigenpairs `(λ, u)` of `G`, and the leading ones come from a block power iteration with a
/// Rayleigh–Ritz step, so the cost is neither cubic in the dimension (`w²·3`, up to 12 288) nor
/// in the subset size. Everything is sequential or per-row, so the basis is the same for any
/// thread count.
fn fit_pca(data: &[f32], dim: usize, components: usize) -> Pca {
    let n = data.len() / dim;
    let m = n.min(PCA_FIT_VECTORS);
    let rows: Vec<&[f32]> = (0..m)
        .map(|i| {
            let r = i * n / m;
            &data[r * dim..(r + 1) * dim]
        })
        .collect();
    let mut mean = vec![0.0f64; dim];
    for r in &rows {
        for (a, &x) in mean.iter_mut().zip(r.iter()) {
            *a += x as f64;
        }
    }
    for a in &mut mean {
        *a /= m.max(1) as f64;
    }
    let centred: Vec<Vec<f64>> = rows
        .iter()
        .map(|r| r.iter().zip(&mean).map(|(&x, &mu)| x as f64 - mu).collect())
        .collect();
    let gram: Vec<f64> = (0..m)
        .into_par_iter()
        .flat_map_iter(|i| {
            let ci = &centred[i];
            centred.iter().map(move |cj| dot(ci, cj))
        })
        .collect();
    let (values, vectors) = leading_eigen(&gram, m, components + 8);
    let top = values.first().copied().unwrap_or(0.0);
    let mut basis = Vec::new();
    for (c, &l) in values.iter().enumerate().take(components) {
        if !(l > top * 1e-9 && l > 0.0) {
            break;
        }
        let mut b = vec![0.0f64; dim];
        for (i, row) in centred.iter().enumerate() {
            let u = vectors[c * m + i];
            for (x, &y) in b.iter_mut().zip(row) {
                *x += u * y;
            }
        }
        let norm = b.iter().map(|x| x * x).sum::<f64>().sqrt();
        basis.extend(b.iter().map(|x| (x / norm) as f32));
    }
    if basis.is_empty() {
        // A flat exemplar: no direction separates anything, but the tree needs one.
        basis = vec![0.0; dim];
        basis[0] = 1.0;
    }
    Pca {
        dim,
        mean: mean.iter().map(|&x| x as f32).collect(),
        basis,
        eigenvalues: values.iter().map(|v| v / (m.max(2) - 1) as f64).collect(),
    }
}

/// Dot product in four interleaved partial sums (vectorizable, and a fixed order).
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0f64; 4];
    let mut ca = a.chunks_exact(4);
    let mut cb = b.chunks_exact(4);
    for (x, y) in (&mut ca).zip(&mut cb) {
        for t in 0..4 {
            acc[t] += x[t] * y[t];
        }
    }
    let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    for (x, y) in ca.remainder().iter().zip(cb.remainder()) {
        s += x * y;
    }
    s
}

/// The `k` leading eigenpairs of the symmetric `n × n` matrix `a` (row-major), eigenvalues
/// decreasing, eigenvectors as rows: block power iteration on `k` vectors, then the
/// Rayleigh–Ritz projection solved by [`symmetric_eigen`].
fn leading_eigen(a: &[f64], n: usize, k: usize) -> (Vec<f64>, Vec<f64>) {
    let k = k.min(n);
    if k == 0 {
        return (Vec::new(), Vec::new());
    }
    // Block as k rows of length n.
    let mut v: Vec<f64> = (0..k * n)
        .map(|i| counter_hash(0x9ca, 0, i as u64) as f64 / u64::MAX as f64 - 0.5)
        .collect();
    let multiply = |v: &[f64]| -> Vec<f64> {
        v.par_chunks(n)
            .flat_map_iter(|row| (0..n).map(move |i| dot(&a[i * n..(i + 1) * n], row)))
            .collect()
    };
    let orthonormalize = |v: &mut [f64]| {
        for r in 0..k {
            let (done, rest) = v.split_at_mut(r * n);
            let row = &mut rest[..n];
            for q in done.chunks_exact(n) {
                let d: f64 = q.iter().zip(row.iter()).map(|(x, y)| x * y).sum();
                for (x, y) in row.iter_mut().zip(q) {
                    *x -= d * y;
                }
            }
            let norm = row.iter().map(|x| x * x).sum::<f64>().sqrt();
            if norm > 1e-300 {
                row.iter_mut().for_each(|x| *x /= norm);
            } else {
                row.iter_mut().for_each(|x| *x = 0.0);
            }
        }
    };
    orthonormalize(&mut v);
    for _ in 0..POWER_ITERATIONS {
        v = multiply(&v);
        orthonormalize(&mut v);
    }
    let av = multiply(&v);
    let mut h = vec![0.0f64; k * k];
    for i in 0..k {
        for j in 0..k {
            h[i * k + j] = v[i * n..(i + 1) * n]
                .iter()
                .zip(&av[j * n..(j + 1) * n])
                .map(|(x, y)| x * y)
                .sum();
        }
    }
    // Symmetrize rounding.
    for i in 0..k {
        for j in i + 1..k {
            let s = 0.5 * (h[i * k + j] + h[j * k + i]);
            h[i * k + j] = s;
            h[j * k + i] = s;
        }
    }
    let (values, small) = symmetric_eigen(&h, k);
    let mut vectors = vec![0.0f64; k * n];
    for c in 0..k {
        for j in 0..k {
            let w = small[c * k + j];
            for (x, y) in vectors[c * n..(c + 1) * n]
                .iter_mut()
                .zip(&v[j * n..(j + 1) * n])
            {
                *x += w * y;
            }
        }
    }
    (values, vectors)
}

/// Unit normals and tangent frames `(u, v = n × u)` per vertex.
fn tangent_frames(mesh: &Mesh, field: &[Vec3]) -> (Vec<Vec3>, Vec<Vec3>, Vec<Vec3>) {
    let normals: Vec<Vec3> = mesh
        .vertex_normals()
        .iter()
        .map(|&n| if n == Vec3::ZERO { Vec3::Z } else { n })
        .collect();
    let mut us = Vec::with_capacity(normals.len());
    let mut vs = Vec::with_capacity(normals.len());
    for (&n, &f) in normals.iter().zip(field) {
        let t = f - n * n.dot(f);
        let u = if t.length_squared() > 1e-16 && t.is_finite() {
            t.normalize()
        } else {
            n.any_orthonormal_vector()
        };
        us.push(u);
        vs.push(n.cross(u));
    }
    (normals, us, vs)
}

/// Greedy X†: in `order`, a referenced vertex becomes a sample unless an earlier sample is
/// within `radius` (Euclidean, reached over edges through vertices within `radius`).
fn choose_samples(mesh: &Mesh, order: &[u32], radius: f32, referenced: &[bool]) -> Vec<u32> {
    let n = mesh.vertex_count();
    let adj = mesh.adjacency();
    let pos = &mesh.positions;
    let mut covered = vec![false; n];
    let mut stamp = vec![u32::MAX; n];
    let mut queue = VecDeque::new();
    let mut samples = Vec::new();
    let r2 = radius * radius;
    for &v in order {
        let v = v as usize;
        if !referenced[v] || covered[v] {
            continue;
        }
        let id = samples.len() as u32;
        samples.push(v as u32);
        queue.clear();
        queue.push_back(v);
        stamp[v] = id;
        covered[v] = true;
        while let Some(a) = queue.pop_front() {
            for &b in adj.neighbors(a) {
                let b = b as usize;
                if stamp[b] == id || pos[b].distance_squared(pos[v]) > r2 {
                    continue;
                }
                stamp[b] = id;
                covered[b] = true;
                queue.push_back(b);
            }
        }
    }
    samples
}

/// Every sample's patch: its vertices with their offsets in texels.
struct Patches {
    /// Per sample, the range of its entries.
    start: Vec<usize>,
    vertex: Vec<u32>,
    offset: Vec<[f32; 2]>,
    /// Per vertex, the indices of the entries covering it, in sample order.
    by_vertex: Csr<u32, usize>,
    /// Sample of each entry.
    entry_sample: Vec<u32>,
}

struct Frames<'a> {
    normals: &'a [Vec3],
    u: &'a [Vec3],
    v: &'a [Vec3],
}

fn gather_patches(
    mesh: &Mesh,
    frames: &Frames,
    samples: &[u32],
    level: Level,
    texel_size: f32,
) -> Patches {
    let n = mesh.vertex_count();
    let adj = mesh.adjacency();
    let pos = &mesh.positions;
    let half = level.extent() * 0.5;
    let radius = half * std::f32::consts::SQRT_2 * texel_size * 1.001;
    let r2 = radius * radius;
    let per_sample: Vec<(Vec<u32>, Vec<[f32; 2]>)> = samples
        .par_iter()
        .map_init(
            || (vec![u32::MAX; n], VecDeque::new()),
            |(stamp, queue), &p| {
                let p = p as usize;
                let (np, up, vp) = (frames.normals[p], frames.u[p], frames.v[p]);
                let mut verts = Vec::new();
                let mut offs = Vec::new();
                queue.clear();
                queue.push_back(p);
                // Samples are distinct vertices, so a sample's own index marks its visits.
                stamp[p] = p as u32;
                while let Some(a) = queue.pop_front() {
                    let d = pos[a] - pos[p];
                    let o = [d.dot(up) / texel_size, d.dot(vp) / texel_size];
                    if o[0].abs() <= half && o[1].abs() <= half {
                        verts.push(a as u32);
                        offs.push(o);
                    }
                    for &b in adj.neighbors(a) {
                        let b = b as usize;
                        if stamp[b] == p as u32
                            || pos[b].distance_squared(pos[p]) > r2
                            || frames.normals[b].dot(np) <= 0.0
                        {
                            continue;
                        }
                        stamp[b] = p as u32;
                        queue.push_back(b);
                    }
                }
                (verts, offs)
            },
        )
        .collect();
    let total: usize = per_sample.iter().map(|x| x.0.len()).sum();
    let mut start = Vec::with_capacity(samples.len() + 1);
    let mut vertex = Vec::with_capacity(total);
    let mut offset = Vec::with_capacity(total);
    let mut entry_sample = Vec::with_capacity(total);
    start.push(0);
    for (i, (v, o)) in per_sample.into_iter().enumerate() {
        entry_sample.extend(std::iter::repeat_n(i as u32, v.len()));
        vertex.extend(v);
        offset.extend(o);
        start.push(vertex.len());
    }
    let by_vertex = Csr::from_pairs(
        n,
        vertex
            .iter()
            .enumerate()
            .map(|(e, &q)| (q as usize, e as u32)),
    );
    Patches {
        start,
        vertex,
        offset,
        by_vertex,
        entry_sample,
    }
}

/// Splits `v` into consecutive mutable pieces at `start` (a CSR offset array).
fn split_by<'a, T>(mut v: &'a mut [T], start: &[usize]) -> Vec<&'a mut [T]> {
    let mut out = Vec::with_capacity(start.len().saturating_sub(1));
    for w in start.windows(2) {
        let (a, b) = v.split_at_mut(w[1] - w[0]);
        out.push(a);
        v = b;
    }
    out
}

#[inline]
fn sq(a: [f32; 3], b: [f32; 3]) -> f32 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)
}

/// Per-level state of the samples.
struct SampleInfo {
    /// λ_p.
    lambda: Vec<f32>,
    /// Curve distance in texels of constrained samples that have candidates; None otherwise.
    constraint: Vec<Option<f32>>,
}

/// Estimated peak memory, in bytes, of synthesis with `patch`-texel patches over an exemplar
/// of `texels` texels and `levels` levels: every candidate patch is kept in full (`patch²`
/// RGB floats per texel, per level), plus the mesh's share (measured: under 200 MB at
/// 200,000 vertices).
pub fn memory_estimate(texels: u64, patch: u64, levels: u64) -> u64 {
    texels * patch * patch * 12 * levels.max(1) + (200 << 20)
}

/// Synthesizes a texture on `input.mesh`; see the module doc. `progress` gets the fraction
/// done after every iteration.
pub fn texture_optimization(
    input: &SurfaceSynthesisInput,
    p: &TextureOptimizationParams,
    progress: &(dyn Fn(f32) + Sync),
) -> Result<SurfaceSynthesis, SynthesisError> {
    p.validate()?;
    let mesh = input.mesh;
    let n = mesh.vertex_count();
    let ex = input.exemplar;
    let (ew, eh) = (ex.width as usize, ex.height as usize);
    if input.field.len() != n {
        return Err(SynthesisError::InputMismatch(format!(
            "the field has {} vectors for {n} vertices",
            input.field.len()
        )));
    }
    if ex.pixels.len() != ew * eh {
        return Err(SynthesisError::InputMismatch(format!(
            "the exemplar is {ew}×{eh} but has {} pixels",
            ex.pixels.len()
        )));
    }
    if !(input.texel_size.is_finite() && input.texel_size > 0.0) {
        return Err(SynthesisError::InputMismatch(format!(
            "texel_size must be a positive number of object units, got {}",
            input.texel_size
        )));
    }
    if !input.exemplar_angle.is_finite() {
        return Err(SynthesisError::InputMismatch(format!(
            "exemplar_angle must be finite, got {}",
            input.exemplar_angle
        )));
    }
    if let Some(f) = &input.features {
        if f.curve_distance.len() != n {
            return Err(SynthesisError::InputMismatch(format!(
                "curve_distance has {} values for {n} vertices",
                f.curve_distance.len()
            )));
        }
        if f.texture_distance.len() != ew * eh {
            return Err(SynthesisError::InputMismatch(format!(
                "texture_distance has {} values for the {ew}×{eh} exemplar",
                f.texture_distance.len()
            )));
        }
    }
    let rot = Rot {
        c: input.exemplar_angle.cos_pure(),
        s: input.exemplar_angle.sin_pure(),
    };
    let w = p.patch as usize;
    let finest = Level { w, step: 1.0 };
    let m = margin(finest, rot);
    if ew.min(eh) < 2 * m + 1 {
        return Err(SynthesisError::ExemplarTooSmall {
            patch: p.patch,
            width: ex.width,
            height: ex.height,
            needed: (2 * m + 1) as u32,
            angle_degrees: input.exemplar_angle.to_degrees(),
        });
    }
    let rgb = Rgb {
        w: ew,
        h: eh,
        px: ex.pixels.iter().map(|c| [c[0], c[1], c[2]]).collect(),
    };
    let mut mean = [0.0f64; 3];
    for c in &rgb.px {
        for k in 0..3 {
            mean[k] += c[k] as f64;
        }
    }
    let mean = mean.map(|x| (x / rgb.px.len().max(1) as f64) as f32);

    let mut referenced = vec![false; n];
    for t in &mesh.triangles {
        for &v in t {
            referenced[v as usize] = true;
        }
    }
    let mut colours = vec![mean; n];
    let mut source = vec![[-1.0f32; 2]; n];
    let mut stats = SynthesisStats::default();
    if !referenced.iter().any(|&r| r) {
        progress(1.0);
        return Ok(SurfaceSynthesis {
            colours,
            source,
            stats,
        });
    }

    let (normals, us, vs) = tangent_frames(mesh, input.field);
    let frames = Frames {
        normals: &normals,
        u: &us,
        v: &vs,
    };
    let h = input.texel_size;
    let curve_texels: Option<Vec<f32>> = input
        .features
        .as_ref()
        .map(|f| f.curve_distance.iter().map(|&d| d / h).collect());

    let levels: Vec<Level> = (0..p.levels)
        .rev()
        .map(|l| Level {
            w,
            step: (1u32 << l) as f32,
        })
        .collect();
    let total_iterations = (levels.len() as u32 * p.iterations) as f32;
    let mut done_iterations = 0u32;
    let mut first = true;
    for (li, &level) in levels.iter().enumerate() {
        let t0 = std::time::Instant::now();
        let Some(cands) = build_candidates(
            &rgb,
            input.features.as_ref().map(|f| f.texture_distance),
            level,
            rot,
            p.components as usize,
        ) else {
            // A coarse level that does not fit: the finest one is checked above.
            done_iterations += p.iterations;
            continue;
        };
        stats.levels_run += 1;
        let band = level.extent() * 0.5;

        // X†.
        let mut order: Vec<(u8, f32, u64, u32)> = (0..n as u32)
            .map(|v| {
                let hash = counter_hash(p.seed, STREAM_ORDER, v as u64);
                match &curve_texels {
                    Some(d) if d[v as usize] < band => (0, d[v as usize], hash, v),
                    _ => (1, 0.0, hash, v),
                }
            })
            .collect();
        order.sort_by(|a, b| {
            a.0.cmp(&b.0)
                .then(a.1.total_cmp(&b.1))
                .then(a.2.cmp(&b.2))
                .then(a.3.cmp(&b.3))
        });
        let order: Vec<u32> = order.into_iter().map(|x| x.3).collect();
        let t1 = std::time::Instant::now();
        let samples = choose_samples(
            mesh,
            &order,
            p.sample_spacing * level.extent() * h,
            &referenced,
        );
        let patches = gather_patches(mesh, &frames, &samples, level, h);
        let t2 = std::time::Instant::now();
        let ns = samples.len();

        let mut info = SampleInfo {
            lambda: vec![1.0; ns],
            constraint: vec![None; ns],
        };
        let (mut constrained, mut fallbacks) = (0u32, 0u32);
        if let Some(d) = &curve_texels {
            for (i, &s) in samples.iter().enumerate() {
                let ds = d[s as usize];
                info.lambda[i] = curve_weight(ds, band, p.min_curve_distance);
                if ds < band {
                    constrained += 1;
                    if cands.any_within(ds, p.feature_tolerance) {
                        info.constraint[i] = Some(ds);
                    } else {
                        fallbacks += 1;
                    }
                }
            }
        }
        stats.samples = ns as u32;
        stats.constrained_samples = constrained;
        stats.unconstrained_fallbacks = fallbacks;

        // Initial matches: random at the first level, else where each sample's vertex came
        // from at the previous level.
        let mut z: Vec<u32> = samples
            .iter()
            .enumerate()
            .map(|(i, &s)| {
                if first {
                    (counter_hash(p.seed, STREAM_INIT, i as u64) % cands.len() as u64) as u32
                } else {
                    cands.nearest_to(source[s as usize])
                }
            })
            .collect();
        let mut lookups = vec![[0.0f32; 3]; patches.vertex.len()];
        refresh_lookups(&mut lookups, &patches, &z, &cands, &rgb, rot);
        if first {
            paste_nearest(
                &patches,
                &lookups,
                &cands,
                &z,
                rot,
                &mut colours,
                &mut source,
            );
            first = false;
        }
        for it in 0..p.iterations {
            let penalty = occurrence_penalty(&z, &cands, p.histogram);
            let new_z = search(&patches, &info, &colours, &z, &cands, level, p, &penalty);
            let changed = new_z != z;
            if it > 0 && !changed {
                break;
            }
            z = new_z;
            refresh_lookups(&mut lookups, &patches, &z, &cands, &rgb, rot);
            // Kopf et al. §3.3: samples matched to over-used exemplar content count less in
            // the colour solve.
            let penalty = occurrence_penalty(&z, &cands, p.histogram);
            let omega: Vec<f32> = patch_errors(&patches, &colours, &lookups)
                .iter()
                .zip(&z)
                .map(|(&e, &zi)| {
                    (e.sqrt() as f32)
                        .max(MIN_PATCH_DISTANCE)
                        .powf_pure(p.robust_exponent - 2.0)
                        / penalty[zi as usize]
                })
                .collect();
            solve_colours(
                &patches,
                &info,
                &omega,
                &lookups,
                &cands,
                &z,
                rot,
                &mut colours,
                &mut source,
            );
            stats.final_energy =
                total_energy(&patches, &info, &colours, &lookups, p.robust_exponent);
            stats.iterations_run += 1;
            done_iterations += 1;
            progress((done_iterations as f32 / total_iterations).min(1.0));
        }
        tracing::debug!(
            "texture optimization level {li}: {} candidates in {:?}, {ns} samples and patches in \
             {:?}, iterations in {:?}",
            cands.len(),
            t1 - t0,
            t2 - t1,
            t2.elapsed()
        );
        done_iterations = (li as u32 + 1) * p.iterations;
        progress((done_iterations as f32 / total_iterations).min(1.0));
    }

    // Vertices no patch covered: from the nearest covered vertex, in edge hops.
    let mut covered: Vec<bool> = source.iter().map(|s| s[0] > -0.5).collect();
    let mut queue: VecDeque<usize> = (0..n).filter(|&v| covered[v]).collect();
    let adj = mesh.adjacency();
    while let Some(a) = queue.pop_front() {
        for &b in adj.neighbors(a) {
            let b = b as usize;
            if !covered[b] && referenced[b] {
                covered[b] = true;
                colours[b] = colours[a];
                source[b] = source[a];
                stats.uncovered_vertices += 1;
                queue.push_back(b);
            }
        }
    }
    progress(1.0);
    Ok(SurfaceSynthesis {
        colours,
        source,
        stats,
    })
}

/// The exemplar colour each patch entry's vertex is asked to take under its sample's match.
fn refresh_lookups(
    lookups: &mut [[f32; 3]],
    patches: &Patches,
    z: &[u32],
    cands: &Candidates,
    rgb: &Rgb,
    rot: Rot,
) {
    split_by(lookups, &patches.start)
        .into_par_iter()
        .enumerate()
        .for_each(|(i, out)| {
            let c = cands.centre(z[i]);
            let base = patches.start[i];
            for (k, o) in out.iter_mut().enumerate() {
                *o = rgb.sample(c + rot.apply(patches.offset[base + k]));
            }
        });
}

/// `|x_p − z_p|²` per sample: squared RGB differences summed over the patch's vertices.
fn patch_errors(patches: &Patches, colours: &[[f32; 3]], lookups: &[[f32; 3]]) -> Vec<f64> {
    (0..patches.start.len() - 1)
        .into_par_iter()
        .map(|i| {
            let mut s = 0.0f64;
            for e in patches.start[i]..patches.start[i + 1] {
                s += sq(colours[patches.vertex[e] as usize], lookups[e]) as f64;
            }
            s
        })
        .collect()
}

fn total_energy(
    patches: &Patches,
    info: &SampleInfo,
    colours: &[[f32; 3]],
    lookups: &[[f32; 3]],
    r: f32,
) -> f64 {
    let errors = patch_errors(patches, colours, lookups);
    errors
        .iter()
        .zip(&info.lambda)
        .map(|(&e, &l)| l as f64 * e.powf_pure(r as f64 * 0.5))
        .sum()
}

/// The least-squares step: each covered vertex takes the `λω`-weighted mean of its patches'
/// lookups, and the source of the heaviest.
#[allow(clippy::too_many_arguments)]
fn solve_colours(
    patches: &Patches,
    info: &SampleInfo,
    omega: &[f32],
    lookups: &[[f32; 3]],
    cands: &Candidates,
    z: &[u32],
    rot: Rot,
    colours: &mut [[f32; 3]],
    source: &mut [[f32; 2]],
) {
    colours
        .par_iter_mut()
        .zip(source.par_iter_mut())
        .enumerate()
        .for_each(|(q, (col, src))| {
            let list = patches.by_vertex.row(q);
            if list.is_empty() {
                return;
            }
            let mut acc = [0.0f32; 3];
            let mut wsum = 0.0f32;
            let mut best = (f32::NEG_INFINITY, 0usize);
            for &e in list {
                let e = e as usize;
                let s = patches.entry_sample[e] as usize;
                let wgt = info.lambda[s] * omega[s];
                for k in 0..3 {
                    acc[k] += wgt * lookups[e][k];
                }
                wsum += wgt;
                if wgt > best.0 {
                    best = (wgt, e);
                }
            }
            if wsum > 0.0 && wsum.is_finite() {
                *col = acc.map(|a| a / wsum);
            } else {
                *col = lookups[best.1];
            }
            let e = best.1;
            let s = patches.entry_sample[e] as usize;
            let at = cands.centre(z[s]) + rot.apply(patches.offset[e]);
            *src = [at.x, at.y];
        });
}

/// Initial colours: every vertex takes the colour its nearest covering sample's (random) patch
/// gives it, so the first search sees sharp pieces of exemplar, not their blurred mean.
fn paste_nearest(
    patches: &Patches,
    lookups: &[[f32; 3]],
    cands: &Candidates,
    z: &[u32],
    rot: Rot,
    colours: &mut [[f32; 3]],
    source: &mut [[f32; 2]],
) {
    colours
        .par_iter_mut()
        .zip(source.par_iter_mut())
        .enumerate()
        .for_each(|(q, (col, src))| {
            let list = patches.by_vertex.row(q);
            let nearest = list.iter().map(|&e| e as usize).min_by(|&a, &b| {
                let (oa, ob) = (patches.offset[a], patches.offset[b]);
                (oa[0] * oa[0] + oa[1] * oa[1]).total_cmp(&(ob[0] * ob[0] + ob[1] * ob[1]))
            });
            if let Some(e) = nearest {
                *col = lookups[e];
                let s = patches.entry_sample[e] as usize;
                let at = cands.centre(z[s]) + rot.apply(patches.offset[e]);
                *src = [at.x, at.y];
            }
        });
}

/// The nearest-neighbour step: every sample's best exemplar patch for the current colours.
#[allow(clippy::too_many_arguments)]
/// Side, in texels, of the exemplar blocks whose use is counted by [`occurrence_penalty`]:
/// single positions are used too rarely (there are more candidates than samples) for a count
/// to mean anything.
const HISTOGRAM_BLOCK: usize = 8;

/// Per candidate, `1 + weight · max(0, use/fair − 1)`: how much more than its fair share the
/// exemplar block around the candidate's centre is used by the current matches (Kopf et al.
/// 2007 §3.3 re-weight by the same excess). Counts come from `z` alone, so the result does not
/// depend on the thread count.
fn occurrence_penalty(z: &[u32], cands: &Candidates, weight: f32) -> Vec<f32> {
    let n = cands.len();
    if weight == 0.0 || n == 0 {
        return vec![1.0; n];
    }
    let ny = n / cands.nx;
    let (bx, by) = (
        cands.nx.div_ceil(HISTOGRAM_BLOCK),
        ny.div_ceil(HISTOGRAM_BLOCK),
    );
    let block = |c: usize| (c / cands.nx / HISTOGRAM_BLOCK) * bx + (c % cands.nx) / HISTOGRAM_BLOCK;
    let mut used = vec![0u32; bx * by];
    for &c in z {
        used[block(c as usize)] += 1;
    }
    // A block's fair share is proportional to the candidates it holds.
    let mut size = vec![0u32; bx * by];
    for c in 0..n {
        size[block(c)] += 1;
    }
    let per_candidate = z.len() as f32 / n as f32;
    (0..n)
        .map(|c| {
            let b = block(c);
            let fair = (size[b] as f32 * per_candidate).max(1.0);
            1.0 + weight * (used[b] as f32 / fair - 1.0).max(0.0)
        })
        .collect()
}

#[allow(clippy::too_many_arguments)]
fn search(
    patches: &Patches,
    info: &SampleInfo,
    colours: &[[f32; 3]],
    z: &[u32],
    cands: &Candidates,
    level: Level,
    p: &TextureOptimizationParams,
    penalty: &[f32],
) -> Vec<u32> {
    let dim = level.dim();
    let cells_per = level.w * level.w;
    let k = cands.pca.components();
    let tree = cands.tree.as_ref();
    (0..z.len())
        .into_par_iter()
        .map_init(
            || (vec![0.0f32; dim], vec![0.0f32; cells_per], vec![0.0f32; k]),
            |(query, weight, proj), i| {
                let current = z[i] as usize;
                let cur_vec = &cands.full[current * dim..(current + 1) * dim];
                // Bilinear splat of the patch's vertices onto the grid: the tent filter the
                // exemplar patches were sampled with.
                query.fill(0.0);
                weight.fill(0.0);
                let centre = (level.w as f32 - 1.0) * 0.5;
                for e in patches.start[i]..patches.start[i + 1] {
                    let o = patches.offset[e];
                    let fx = o[0] / level.step + centre;
                    let fy = o[1] / level.step + centre;
                    let (x0, y0) = (fx.floor(), fy.floor());
                    let (tx, ty) = (fx - x0, fy - y0);
                    let col = colours[patches.vertex[e] as usize];
                    for (dx, dy, wgt) in [
                        (0, 0, (1.0 - tx) * (1.0 - ty)),
                        (1, 0, tx * (1.0 - ty)),
                        (0, 1, (1.0 - tx) * ty),
                        (1, 1, tx * ty),
                    ] {
                        let (cx, cy) = (x0 as i64 + dx, y0 as i64 + dy);
                        if wgt <= 0.0
                            || cx < 0
                            || cy < 0
                            || cx >= level.w as i64
                            || cy >= level.w as i64
                        {
                            continue;
                        }
                        let c = cy as usize * level.w + cx as usize;
                        weight[c] += wgt;
                        for t in 0..3 {
                            query[c * 3 + t] += wgt * col[t];
                        }
                    }
                }
                let mut missing = 0usize;
                for c in 0..cells_per {
                    if weight[c] > 1e-4 {
                        for t in 0..3 {
                            query[c * 3 + t] /= weight[c];
                        }
                    } else {
                        weight[c] = 0.0;
                        missing += 1;
                        query[c * 3..c * 3 + 3].copy_from_slice(&cur_vec[c * 3..c * 3 + 3]);
                    }
                }
                // The occurrence penalty needs alternatives to choose from.
                let search_k = if missing * 10 > cells_per || p.histogram > 0.0 {
                    SEARCH_K_PARTIAL
                } else {
                    SEARCH_K
                };
                // Distance over the grid cells the patch's vertices reach.
                let masked = |cand: &[f32]| -> f32 {
                    if missing == 0 {
                        return squared_distance(query, cand);
                    }
                    let mut acc = 0.0f32;
                    for c in 0..cells_per {
                        if weight[c] > 0.0 {
                            for t in 0..3 {
                                let d = query[c * 3 + t] - cand[c * 3 + t];
                                acc += d * d;
                            }
                        }
                    }
                    acc
                };
                cands.pca.project(query, proj);
                let found = match (info.constraint[i], &cands.distance) {
                    (Some(d), Some((dist, _))) => {
                        let tol = p.feature_tolerance;
                        tree.nearest_approx(proj, search_k, p.search_eps, |c| {
                            (dist[c as usize] - d).abs() <= tol
                        })
                    }
                    _ => tree.nearest_approx(proj, search_k, p.search_eps, |_| true),
                };
                // The current match competes too, if it satisfies the constraint.
                let current_allowed = match (info.constraint[i], &cands.distance) {
                    (Some(d), Some((dist, _))) => (dist[current] - d).abs() <= p.feature_tolerance,
                    _ => true,
                };
                let mut best = (f32::INFINITY, u32::MAX);
                if current_allowed {
                    best = (masked(cur_vec) * penalty[current], current as u32);
                }
                for (c, _) in found {
                    let cu = c as usize;
                    let d = masked(&cands.full[cu * dim..(cu + 1) * dim]) * penalty[cu];
                    if d < best.0 || (d == best.0 && c < best.1) {
                        best = (d, c);
                    }
                }
                if best.1 == u32::MAX { z[i] } else { best.1 }
            },
        )
        .collect()
}

/// Geodesic distance from `sources` to every vertex, in object units (∞ where no source can be
/// reached; out-of-range source indices are ignored).
///
/// Dijkstra over edges, where a vertex `c` of a triangle whose other two corners `a`, `b` are
/// final also gets fast marching's update: the distance taken linear over the triangle with a
/// unit gradient, when the front so defined reaches `c` through the edge `ab`. Distances from a
/// straight row of vertices on a flat grid are exact (tested). From a single vertex on a
/// triangulated grid (one diagonal per cell), beyond five edges the overestimate is 2.4% on
/// average and 10% at worst (near the source, across the diagonals), against 17% and 41% for
/// edges alone; the error shrinks with the distance from the source. Feature curves are
/// sources along a line, where the front is nearly planar and the update nearly exact.
pub fn curve_distance(mesh: &Mesh, sources: &[u32]) -> Vec<f32> {
    geodesic(mesh, sources, true)
}

/// Dijkstra from `sources`, with the triangle updates when `through_triangles`.
fn geodesic(mesh: &Mesh, sources: &[u32], through_triangles: bool) -> Vec<f32> {
    let n = mesh.vertex_count();
    let pos = &mesh.positions;
    let adj = mesh.adjacency();
    let tris = mesh.vertex_faces();
    let mut search = Dijkstra::new(n, ());
    for &s in sources {
        if (s as usize) < n {
            search.add_source(s);
        }
    }
    let p64 = |v: usize| pos[v].as_dvec3();
    search.run(&[], |search, v, d| {
        // The triangle updates can offer a settled vertex less than it has: only unsettled
        // vertices are relaxed.
        for &c in adj.neighbors(v as usize) {
            if !search.is_settled(c) {
                let nd = d + (p64(c as usize) - p64(v as usize)).length();
                search.relax(c, nd, ());
            }
        }
        if !through_triangles {
            return;
        }
        for &f in tris.row(v as usize) {
            let t = mesh.triangles[f as usize];
            for k in 0..3 {
                let a = t[k];
                let c = t[(k + 1) % 3];
                if a == v || c == v {
                    continue;
                }
                for (a, c) in [(a, c), (c, a)] {
                    if search.is_settled(a)
                        && !search.is_settled(c)
                        && let Some(nd) = unfold(
                            p64(v as usize),
                            d,
                            p64(a as usize),
                            search.dist(a),
                            p64(c as usize),
                        )
                    {
                        search.relax(c, nd, ());
                    }
                }
            }
        }
    });
    search.distances().iter().map(|&d| d as f32).collect()
}

/// Fast marching's update of corner `c` of a triangle from its corners `a`, `b` with distances
/// `da`, `db`: the distance is taken linear over the triangle with a unit gradient (a planar
/// front, exact for a straight curve), pointing from edge `ab` towards `c`; None when that
/// front cannot reach `c` through the edge (then the edge updates decide).
fn unfold(a: glam::DVec3, da: f64, b: glam::DVec3, db: f64, c: glam::DVec3) -> Option<f64> {
    let ab = b - a;
    let l = ab.length();
    if l <= 0.0 {
        return None;
    }
    let e = ab / l;
    let ac = c - a;
    let xc = ac.dot(e);
    let yc = (ac - e * xc).length();
    if yc <= 0.0 {
        return None;
    }
    let gx = (db - da) / l;
    if gx.abs() > 1.0 {
        return None;
    }
    let gy = (1.0 - gx * gx).sqrt();
    if gy <= 0.0 {
        return None;
    }
    // Where the characteristic through c crosses the edge.
    let cross = xc - gx * yc / gy;
    if !(0.0..=l).contains(&cross) {
        return None;
    }
    Some(da + gx * xc + gy * yc)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::primitives::grid;
    use crate::image::patch_score::{ScoreParams, patch_score};
    use crate::random::counter_unit;
    use crate::testing::assert_validation;

    fn no_progress(_: f32) {}

    /// Horizontal stripes (colour changes along y only) of random widths 3..=7 and random
    /// colours, with a little pixel noise so that no two patches are identical.
    fn striped(size: u32, seed: u64) -> Image {
        let mut rows = Vec::new();
        let mut k = 0u64;
        while rows.len() < size as usize {
            let width = 3 + (counter_hash(seed, 10, k) % 5) as usize;
            let c = [
                0.15 + 0.7 * counter_unit(seed, 11, k),
                0.15 + 0.7 * counter_unit(seed, 12, k),
                0.15 + 0.7 * counter_unit(seed, 13, k),
            ];
            rows.extend(std::iter::repeat_n(c, width));
            k += 1;
        }
        Image::from_fn(size, size, |x, y| {
            let c = rows[y as usize];
            let i = (y * size + x) as u64;
            let nz = |s| 0.03 * (counter_unit(seed, s, i) - 0.5);
            [c[0] + nz(20), c[1] + nz(21), c[2] + nz(22), 1.0]
        })
    }

    fn constant_field(n: usize, dir: Vec3) -> Vec<Vec3> {
        vec![dir; n]
    }

    /// The grid's vertex colours as an image (vertex (x, y) is pixel (x, y)).
    fn as_image(colours: &[[f32; 3]], side: usize) -> Image {
        Image::from_fn(side as u32, side as u32, |x, y| {
            let c = colours[y as usize * side + x as usize];
            [c[0], c[1], c[2], 1.0]
        })
    }

    fn preview(name: &str, img: &Image) {
        if std::env::var_os("TOPT_PREVIEW").is_some() {
            let scale = 4;
            let big = image::imageops::resize(
                &img.to_rgba8(),
                img.width * scale,
                img.height * scale,
                image::imageops::FilterType::Nearest,
            );
            big.save(format!("/tmp/topt-{name}.png")).unwrap();
        }
    }

    /// Mean absolute colour difference between neighbours along x and along y.
    fn directional_differences(c: &[[f32; 3]], side: usize) -> (f64, f64) {
        let (mut dx, mut dy) = (0.0f64, 0.0f64);
        let mut count = 0usize;
        for y in 0..side - 1 {
            for x in 0..side - 1 {
                let a = c[y * side + x];
                let b = c[y * side + x + 1];
                let d = c[(y + 1) * side + x];
                for k in 0..3 {
                    dx += (a[k] - b[k]).abs() as f64;
                    dy += (a[k] - d[k]).abs() as f64;
                }
                count += 1;
            }
        }
        (dx / count as f64, dy / count as f64)
    }

    fn synth(
        mesh: &Mesh,
        field: &[Vec3],
        ex: &Image,
        features: Option<FeatureConstraint>,
        p: &TextureOptimizationParams,
    ) -> SurfaceSynthesis {
        let input = SurfaceSynthesisInput {
            mesh,
            field,
            exemplar: ex,
            texel_size: 1.0,
            exemplar_angle: 0.0,
            features,
        };
        texture_optimization(&input, p, &no_progress).unwrap()
    }

    #[test]
    fn parameters_are_validated() {
        assert_validation!(TextureOptimizationParams {
            patch: 3 => "synthesize.patch must be in 4..=64, got 3",
            sample_spacing: 0.0 => "synthesize.sample_spacing must be in 0.05..=1, got 0",
            robust_exponent: 3.0 => "synthesize.robust_exponent must be in 0.1..=2, got 3",
            iterations: 0 => "synthesize.iterations must be in 1..=100, got 0",
            feature_tolerance: -1.0 => "synthesize.feature_tolerance must be in 0..=64, got -1",
            levels: 4 => "synthesize.levels must be in 1..=3, got 4",
            components: 2 => "synthesize.components must be in 4..=64, got 2",
            search_eps: f32::NAN => "synthesize.search_eps must be in 0..=10, got NaN",
            min_curve_distance: 0.0 => "synthesize.min_curve_distance must be in 0.000001..=64, got 0",
            histogram: -1.0 => "synthesize.histogram must be in 0..=10, got -1",
        });
    }

    #[test]
    fn stripes_follow_the_field_and_look_like_the_exemplar() {
        let side = 64;
        let mesh = grid(side, 1.0);
        let ex = striped(64, 3);
        // Plain texture optimization (no occurrence penalty): the scores below were measured
        // for it; the penalty is tested on its own below.
        let p = TextureOptimizationParams {
            histogram: 0.0,
            ..Default::default()
        };
        let out = synth(&mesh, &constant_field(side * side, Vec3::X), &ex, None, &p);
        let img = as_image(&out.colours, side);
        preview("stripes-x", &img);
        let (along, across) = directional_differences(&out.colours, side);
        assert!(
            along < 0.3 * across,
            "stripes do not run along u = x: along {along:.4}, across {across:.4}"
        );
        // Nearest-patch score: this exemplar's unique stripe colours make its self baseline
        // tiny (a crop's patches recur elsewhere along their stripe), so one seam between two
        // stripe layouts already doubles the ratio; measured 1.27, 1.96, 2.76 for seeds 0..3,
        // while a single level, plain least squares (r = 2) or a too large patch give 3.4–8.
        let mut ratios = Vec::new();
        for seed in 0..3 {
            let o = if seed == 0 {
                out.clone()
            } else {
                let p = TextureOptimizationParams { seed, ..p.clone() };
                synth(&mesh, &constant_field(side * side, Vec3::X), &ex, None, &p)
            };
            let score = patch_score(
                as_image(&o.colours, side).view(),
                ex.view(),
                &ScoreParams {
                    patch: 7,
                    ..Default::default()
                },
            )
            .unwrap();
            ratios.push(score.ratio);
        }
        let mean_ratio = ratios.iter().sum::<f64>() / 3.0;
        assert!(mean_ratio < 2.5, "patch score ratios {ratios:?}");
        assert_eq!(out.stats.uncovered_vertices, 0);
        assert!(out.stats.samples > 0 && out.stats.samples < (side * side / 8) as u32);

        // The field turned by 90° turns the stripes.
        let out = synth(&mesh, &constant_field(side * side, Vec3::Y), &ex, None, &p);
        preview("stripes-y", &as_image(&out.colours, side));
        let (along_x, along_y) = directional_differences(&out.colours, side);
        assert!(
            along_y < 0.3 * along_x,
            "stripes do not run along u = y: along y {along_y:.4}, along x {along_x:.4}"
        );
    }

    /// A synthetic brick wall: light bricks 24×12 texels with a little noise, dark mortar rows
    /// and joints two texels wide (joints offset by half a brick every row).
    fn bricks(size: u32) -> Image {
        let mut img = Image::new(size, size);
        for y in 0..size {
            for x in 0..size {
                let row = y / 12;
                let xs = x + if row % 2 == 1 { 12 } else { 0 };
                let mortar = y % 12 < 2 || xs % 24 < 2;
                let n = crate::random::counter_unit(5, 0, (y * size + x) as u64) * 0.1;
                let v = if mortar { 0.1 + n * 0.5 } else { 0.7 + n };
                img.pixels[(y * size + x) as usize] = [v, v * 0.8, v * 0.6, 1.0];
            }
        }
        img
    }

    #[test]
    fn the_occurrence_penalty_keeps_rare_features() {
        // Mortar covers about a quarter of the wall. Plain texture optimization may settle on
        // brick interior (every 15-texel window of a brick is a perfect match for itself), and
        // the mortar fraction of the result drops; the penalty keeps it near the exemplar's.
        let side = 96;
        let mesh = grid(side, 1.0);
        let ex = bricks(96);
        let dark = |c: &[[f32; 3]]| c.iter().filter(|c| c[0] < 0.4).count() as f64 / c.len() as f64;
        let ex_rgb: Vec<[f32; 3]> = ex.pixels.iter().map(|p| [p[0], p[1], p[2]]).collect();
        let target = dark(&ex_rgb);
        let error = |histogram: f32| {
            (0..3)
                .map(|seed| {
                    let p = TextureOptimizationParams {
                        histogram,
                        seed,
                        ..Default::default()
                    };
                    let out = synth(&mesh, &constant_field(side * side, Vec3::X), &ex, None, &p);
                    preview(
                        &format!("bricks-h{histogram}-{seed}"),
                        &as_image(&out.colours, side),
                    );
                    (dark(&out.colours) - target).abs()
                })
                .sum::<f64>()
                / 3.0
        };
        let (plain, penalized) = (error(0.0), error(1.0));
        assert!(
            penalized < plain,
            "mortar fraction off by {penalized:.3} with the penalty, {plain:.3} without (exemplar {target:.3})"
        );
    }

    /// A textured background with three dark horizontal lines one texel thick, and each
    /// texel's distance to the nearest line.
    fn lined(size: u32) -> (Image, Vec<f32>) {
        let lines = [12i64, 30, 47];
        let dist = |y: u32| {
            lines
                .iter()
                .map(|&l| (y as i64 - l).abs() as f32)
                .fold(f32::INFINITY, f32::min)
        };
        let img = Image::from_fn(size, size, |x, y| {
            if dist(y) == 0.0 {
                [0.08, 0.06, 0.05, 1.0]
            } else {
                let i = (y * size + x) as u64;
                let blob = 0.5
                    + 0.15
                        * ((x as f32 * 0.45).sin_pure()
                            * (y as f32 * 0.3 + x as f32 * 0.1).cos_pure())
                    + 0.06 * (counter_unit(5, 1, i) - 0.5);
                [blob + 0.2, blob + 0.1, blob * 0.6, 1.0]
            }
        });
        let td = (0..size * size).map(|i| dist(i / size)).collect();
        (img, td)
    }

    #[test]
    fn the_constraint_puts_texture_lines_on_the_shape_curve() {
        let side = 64;
        let mesh = grid(side, 1.0);
        let curve: Vec<u32> = (0..side as u32).map(|x| 32 * side as u32 + x).collect();
        let d = curve_distance(&mesh, &curve);
        let (ex, td) = lined(64);
        let field = constant_field(side * side, Vec3::X);
        let p = TextureOptimizationParams::default();
        let free = synth(&mesh, &field, &ex, None, &p);
        let constrained = synth(
            &mesh,
            &field,
            &ex,
            Some(FeatureConstraint {
                curve_distance: &d,
                texture_distance: &td,
            }),
            &p,
        );
        preview("lines-free", &as_image(&free.colours, side));
        preview("lines-constrained", &as_image(&constrained.colours, side));
        assert!(constrained.stats.constrained_samples > 0);
        assert_eq!(constrained.stats.unconstrained_fallbacks, 0);
        let d_at = |s: [f32; 2]| {
            let x = (s[0].round() as usize).min(63);
            let y = (s[1].round() as usize).min(63);
            td[y * 64 + x]
        };
        let band = p.patch as f32 * 0.5;
        let mismatch = |out: &SurfaceSynthesis| {
            let (mut sum, mut count) = (0.0f64, 0usize);
            for v in 0..side * side {
                if d[v] < band {
                    sum += (d_at(out.source[v]) - d[v]).abs() as f64;
                    count += 1;
                }
            }
            sum / count as f64
        };
        let (m_free, m_con) = (mismatch(&free), mismatch(&constrained));
        assert!(
            m_con <= 0.5 * m_free,
            "mean |D(source) − d| with the constraint {m_con:.3}, without {m_free:.3}"
        );
        // The acceptance measure: from each curve vertex, the distance to the nearest vertex
        // whose colour comes from a texture line.
        let line_distance = |out: &SurfaceSynthesis| {
            let on_line: Vec<Vec3> = (0..side * side)
                .filter(|&v| d_at(out.source[v]) < 0.5)
                .map(|v| mesh.positions[v])
                .collect();
            let total: f32 = curve
                .iter()
                .map(|&c| {
                    let pc = mesh.positions[c as usize];
                    on_line
                        .iter()
                        .map(|q| q.distance(pc))
                        .fold(f32::INFINITY, f32::min)
                })
                .sum();
            total / curve.len() as f32
        };
        let (l_free, l_con) = (line_distance(&free), line_distance(&constrained));
        eprintln!("mismatch {m_free:.3} -> {m_con:.3}, line distance {l_free:.3} -> {l_con:.3}");
        assert!(
            l_con <= 0.5 * l_free,
            "curve to nearest texture line: {l_con:.3} with the constraint, {l_free:.3} without"
        );
        // On the curve itself the texture's line lies there, visibly dark.
        let on_curve = |out: &SurfaceSynthesis| {
            let (mut dsum, mut lum) = (0.0f64, 0.0f64);
            for &v in &curve {
                dsum += d_at(out.source[v as usize]) as f64;
                let c = out.colours[v as usize];
                lum += ((c[0] + c[1] + c[2]) / 3.0) as f64;
            }
            (dsum / curve.len() as f64, lum / curve.len() as f64)
        };
        let (dist_con, lum_con) = on_curve(&constrained);
        assert!(
            dist_con < 1.0,
            "on-curve vertices come from {dist_con:.2} texels off a line"
        );
        assert!(lum_con < 0.2, "the curve's row is not dark: {lum_con:.3}");
    }

    #[test]
    fn more_iterations_lower_the_energy() {
        let side = 48;
        let mesh = grid(side, 1.0);
        let ex = striped(48, 9);
        let field = constant_field(side * side, Vec3::X);
        let run = |iterations| {
            let p = TextureOptimizationParams {
                iterations,
                levels: 1,
                ..Default::default()
            };
            synth(&mesh, &field, &ex, None, &p).stats
        };
        let (one, many) = (run(1), run(10));
        assert_eq!(one.iterations_run, 1);
        assert!(many.iterations_run > 1);
        assert!(
            many.final_energy < one.final_energy,
            "energy after {} iterations {} is not below that after one, {}",
            many.iterations_run,
            many.final_energy,
            one.final_energy
        );
    }

    #[test]
    fn results_do_not_depend_on_the_thread_count() {
        let side = 40;
        let mesh = grid(side, 1.0);
        let curve: Vec<u32> = (0..side as u32).map(|x| 20 * side as u32 + x).collect();
        let d = curve_distance(&mesh, &curve);
        let (ex, td) = lined(64);
        // A field that turns, so that offsets are not whole texels.
        let field: Vec<Vec3> = mesh
            .positions
            .iter()
            .map(|q| Vec3::new(1.0, 0.02 * q.x, 0.0))
            .collect();
        let run = |threads| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let input = SurfaceSynthesisInput {
                    mesh: &mesh,
                    field: &field,
                    exemplar: &ex,
                    texel_size: 1.0,
                    exemplar_angle: 0.3,
                    features: Some(FeatureConstraint {
                        curve_distance: &d,
                        texture_distance: &td,
                    }),
                };
                let p = TextureOptimizationParams {
                    patch: 9,
                    ..Default::default()
                };
                texture_optimization(&input, &p, &no_progress).unwrap()
            })
        };
        let (a, b) = (run(1), run(2));
        let bits = |o: &SurfaceSynthesis| {
            let c: Vec<u32> = o.colours.iter().flatten().map(|x| x.to_bits()).collect();
            let s: Vec<u32> = o.source.iter().flatten().map(|x| x.to_bits()).collect();
            (c, s)
        };
        assert_eq!(bits(&a), bits(&b));
        assert_eq!(a.stats, b.stats);
    }

    #[test]
    fn bad_input_is_an_error_naming_what_to_change() {
        let mesh = grid(8, 1.0);
        let field = constant_field(64, Vec3::X);
        let ex = striped(48, 1);
        let input = |field: &'static [Vec3]| SurfaceSynthesisInput {
            mesh: &mesh,
            field,
            exemplar: &ex,
            texel_size: 1.0,
            exemplar_angle: 0.0,
            features: None,
        };
        let field: &'static [Vec3] = field.leak();
        let big = TextureOptimizationParams {
            patch: 64,
            ..Default::default()
        };
        let e = texture_optimization(&input(field), &big, &no_progress).unwrap_err();
        assert!(matches!(e, SynthesisError::ExemplarTooSmall { .. }), "{e}");
        assert!(e.to_string().contains("synthesize.patch"), "{e}");
        // A patch that fits unrotated does not fit at 45°.
        let fits = TextureOptimizationParams {
            patch: 40,
            ..Default::default()
        };
        assert!(texture_optimization(&input(field), &fits, &no_progress).is_ok());
        let mut turned = input(field);
        turned.exemplar_angle = std::f32::consts::FRAC_PI_4;
        assert!(matches!(
            texture_optimization(&turned, &fits, &no_progress),
            Err(SynthesisError::ExemplarTooSmall { .. })
        ));
        let e = texture_optimization(&input(&field[1..]), &fits, &no_progress).unwrap_err();
        assert!(matches!(e, SynthesisError::InputMismatch(_)), "{e}");
        let d = vec![0.0f32; 63];
        let td = vec![0.0f32; 48 * 48];
        let mut wrong = input(field);
        wrong.features = Some(FeatureConstraint {
            curve_distance: &d,
            texture_distance: &td,
        });
        assert!(matches!(
            texture_optimization(&wrong, &fits, &no_progress),
            Err(SynthesisError::InputMismatch(_))
        ));
        let mut zero = input(field);
        zero.texel_size = 0.0;
        assert!(matches!(
            texture_optimization(&zero, &fits, &no_progress),
            Err(SynthesisError::InputMismatch(_))
        ));
        let bad = TextureOptimizationParams {
            iterations: 0,
            ..Default::default()
        };
        assert!(matches!(
            texture_optimization(&input(field), &bad, &no_progress),
            Err(SynthesisError::Params(_))
        ));
    }

    #[test]
    fn curve_weight_is_one_over_distance_in_the_band_capped_and_flat_outside() {
        let (band, floor) = (7.5, 0.25);
        assert_eq!(curve_weight(2.0, band, floor), 0.5);
        assert_eq!(curve_weight(0.0, band, floor), 4.0);
        assert_eq!(curve_weight(0.1, band, floor), 4.0);
        // Continuous at the band's edge, constant beyond, NaN and ∞ are far.
        assert!((curve_weight(7.4999, band, floor) - 1.0 / 7.5).abs() < 1e-5);
        assert_eq!(curve_weight(7.5, band, floor), 1.0 / 7.5);
        assert_eq!(curve_weight(100.0, band, floor), 1.0 / 7.5);
        assert_eq!(curve_weight(f32::INFINITY, band, floor), 1.0 / 7.5);
        assert_eq!(curve_weight(f32::NAN, band, floor), 1.0 / 7.5);
        // The paper's literal law with the floor at ε₀.
        assert_eq!(curve_weight(0.0, band, 1e-6), 1e6);
    }

    #[test]
    fn curve_distance_is_near_euclidean_on_a_flat_grid() {
        let side = 41;
        let mesh = grid(side, 0.5);
        let centre = (20 * side + 20) as u32;
        let c = mesh.positions[centre as usize];
        // (max, mean) relative error beyond five edges.
        let error = |d: &[f32]| {
            let (mut worst, mut sum, mut count) = (0.0f32, 0.0f32, 0);
            for (v, q) in mesh.positions.iter().enumerate() {
                let e = q.distance(c);
                assert!(
                    d[v] >= e * 0.999,
                    "below the straight line at {v}: {} < {e}",
                    d[v]
                );
                if e > 2.5 {
                    let r = (d[v] - e) / e;
                    worst = worst.max(r);
                    sum += r;
                    count += 1;
                }
            }
            (worst, sum / count as f32)
        };
        let (worst, mean) = error(&curve_distance(&mesh, &[centre]));
        let (worst_edges, mean_edges) = error(&geodesic(&mesh, &[centre], false));
        eprintln!(
            "point source: max {worst:.4} mean {mean:.4}; edges only {worst_edges:.4} {mean_edges:.4}"
        );
        assert!(worst < 0.5 * worst_edges && mean < 0.5 * mean_edges);
        assert!(
            worst < 0.12 && mean < 0.03,
            "relative error max {worst}, mean {mean}"
        );
        // A straight row: exactly the distance to it.
        let row: Vec<u32> = (0..side as u32).map(|x| 10 * side as u32 + x).collect();
        let d = curve_distance(&mesh, &row);
        for (v, q) in mesh.positions.iter().enumerate() {
            assert!((d[v] - (q.y - 5.0).abs()).abs() < 1e-4, "{v}: {}", d[v]);
        }
        // Unreachable vertices and no sources.
        let mut m = grid(3, 1.0);
        m.positions.push(Vec3::splat(9.0));
        let m = Mesh::new(m.positions.clone(), m.triangles.clone());
        let d = curve_distance(&m, &[0, 99]);
        assert_eq!(d[0], 0.0);
        assert_eq!(d[9], f32::INFINITY);
        assert!(curve_distance(&m, &[]).iter().all(|x| x.is_infinite()));
    }

    /// Prints quality measures for a few settings (a tuning aid, not a check).
    #[test]
    #[ignore]
    fn explore_settings() {
        let side = 64;
        let mesh = grid(side, 1.0);
        let ex = striped(64, 3);
        let field = constant_field(side * side, Vec3::X);
        let base = TextureOptimizationParams::default();
        let variants = [
            ("default", base.clone()),
            (
                "it6",
                TextureOptimizationParams {
                    iterations: 6,
                    ..base.clone()
                },
            ),
            (
                "it20",
                TextureOptimizationParams {
                    iterations: 20,
                    ..base.clone()
                },
            ),
            (
                "levels1it30",
                TextureOptimizationParams {
                    levels: 1,
                    iterations: 30,
                    ..base.clone()
                },
            ),
            (
                "levels3",
                TextureOptimizationParams {
                    levels: 3,
                    ..base.clone()
                },
            ),
            (
                "r2",
                TextureOptimizationParams {
                    robust_exponent: 2.0,
                    ..base.clone()
                },
            ),
            (
                "w9",
                TextureOptimizationParams {
                    patch: 9,
                    ..base.clone()
                },
            ),
            (
                "w21",
                TextureOptimizationParams {
                    patch: 21,
                    ..base.clone()
                },
            ),
            (
                "s0.15",
                TextureOptimizationParams {
                    sample_spacing: 0.15,
                    ..base.clone()
                },
            ),
        ];
        for (name, p) in variants {
            for seed in 0..3 {
                let p = TextureOptimizationParams { seed, ..p.clone() };
                let t = std::time::Instant::now();
                let out = synth(&mesh, &field, &ex, None, &p);
                let img = as_image(&out.colours, side);
                let score = patch_score(
                    img.view(),
                    ex.view(),
                    &ScoreParams {
                        patch: 7,
                        ..Default::default()
                    },
                )
                .unwrap();
                let (along, across) = directional_differences(&out.colours, side);
                eprintln!(
                    "{name:10} ratio {:.3} grad {:.3} along/across {:.3} its {} energy {:.1} {:?}",
                    score.ratio,
                    score.gradient_ratio,
                    along / across,
                    out.stats.iterations_run,
                    out.stats.final_energy,
                    t.elapsed()
                );
                preview(&format!("explore-{name}-{seed}"), &img);
            }
        }
    }

    /// Time for a ~100k-vertex grid with a 128² exemplar at the defaults (run with
    /// `--release -- --ignored timing --nocapture`; reads ../shared/data when it is there).
    #[test]
    #[ignore]
    fn timing_100k_vertices() {
        let side = 317;
        let mesh = grid(side, 1.0);
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../shared/data/exemplars/crinklepaper.png");
        let ex = match std::fs::read(&path) {
            Ok(bytes) => crate::image::decode_image(&path, &bytes).unwrap(),
            Err(_) => striped(128, 1),
        };
        let field = constant_field(side * side, Vec3::X);
        let p = TextureOptimizationParams::default();
        let t = std::time::Instant::now();
        let out = synth(&mesh, &field, &ex, None, &p);
        eprintln!(
            "{} vertices, {}×{} exemplar, unconstrained: {:?}, {:?}",
            side * side,
            ex.width,
            ex.height,
            t.elapsed(),
            out.stats
        );
        preview("crinkle-100k", &as_image(&out.colours, side));
        let (lex, td) = lined(128);
        let curve: Vec<u32> = (0..side as u32).map(|x| 158 * side as u32 + x).collect();
        let t = std::time::Instant::now();
        let d = curve_distance(&mesh, &curve);
        let td_time = t.elapsed();
        let t = std::time::Instant::now();
        let out = synth(
            &mesh,
            &field,
            &lex,
            Some(FeatureConstraint {
                curve_distance: &d,
                texture_distance: &td,
            }),
            &p,
        );
        eprintln!(
            "constrained: curve distance {td_time:?}, synthesis {:?}, {:?}",
            t.elapsed(),
            out.stats
        );
        preview("lines-100k", &as_image(&out.colours, side));
    }
}
