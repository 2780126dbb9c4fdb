//! The synthesis' parameters and their validation, its input (mesh, field, exemplar, feature
//! constraint), its output and statistics, its errors, and its memory estimate.

use crate::check::{ParamError, check_range};
use crate::geom::Mesh;
use crate::image::Image;
use glam::Vec3;
use serde::{Deserialize, Serialize};

/// Parameters of [`texture_optimization`](super::texture_optimization).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TextureOptimizationParams {
    /// Patch side `w` in exemplar texels at the finest level, 4..=64. Default: 15 — odd, so the
    /// matching grid sits on pixel centres (see the module doc); 15 spans a stripe or a
    /// brick row of a typical 64–128 px exemplar, and with the default two levels the coarse
    /// level sees 30 texels, Kwatra's large-patch pass.
    pub patch: u32,
    /// The paper's `r`: samples are at most `r·w` texels apart, 0.05..=1. Default: 0.25
    /// (the paper's value; each vertex is then covered by about 16 patches). Above 0.5 (about
    /// 0.4 across creases) some vertices may be covered by no patch.
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
    /// Pull toward coherent matches, 0..=0.95: each sample also considers the exemplar
    /// patches that continue what its patch's vertices copy at the current iteration
    /// (k-coherence candidates, see the module doc), at `1 − coherence` times their distance.
    /// 0 leaves them out: the plain nearest-patch search. Default: 0.6, chosen on fandisk and
    /// checked on the other shipped configs (fandisk at 0 vs 0.6: gradient ratio 0.68 vs
    /// 0.70, coverage 0.72 vs 0.78, nearest-patch ratio 0.78 vs 0.77; whole stones with their
    /// mortar instead of fragments).
    pub coherence: f32,
    /// How the finest level's final colours are made from the patches that cover each vertex.
    /// Default: `discrete`.
    pub solver: Solver,
}

/// The colour solve of each iteration (see the module doc, "Discrete solve").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Solver {
    /// The iterations as `average`, then one discrete pass: each vertex copies the exemplar
    /// texel that its best-matching covering patch (largest `λ_p ω_p`) gives it, so colours
    /// stay the exemplar's own and each vertex keeps the exemplar address it came from.
    #[default]
    Discrete,
    /// Kwatra et al. 2005's continuous solve to the end: each vertex the weighted mean of the
    /// patches that cover it (about 16 at the default spacing), which blurs what they
    /// disagree on.
    Average,
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
            coherence: 0.6,
            solver: Solver::Discrete,
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
        check_range("synthesize.histogram", self.histogram, 0.0, 10.0)?;
        check_range("synthesize.coherence", self.coherence, 0.0, 0.95)
    }
}

/// What [`texture_optimization`](super::texture_optimization) synthesizes on.
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
    /// colour came from: with the discrete solver, exactly the address whose bilinear lookup is
    /// its colour; with the average, the address in the covering patch of largest weight.
    /// `[-1, -1]` for vertices used by no triangle.
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

/// Why [`texture_optimization`](super::texture_optimization) cannot run.
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

/// Estimated peak memory, in bytes, of synthesis with `patch`-texel patches over an exemplar
/// of `texels` texels and `levels` levels: every candidate patch is kept in full (`patch²`
/// RGB floats per texel, per level), plus the mesh's share (measured: under 200 MB at
/// 200,000 vertices).
pub fn memory_estimate(texels: u64, patch: u64, levels: u64) -> u64 {
    texels * patch * patch * 12 * levels.max(1) + (200 << 20)
}
