//! Geometric texture synthesis over a geometry image, consistent across its cuts.
//!
//! Implements Y.-K. Lai, S.-M. Hu, D. X. Gu and R. R. Martin, "Geometric Texture Synthesis and
//! Transfer via Geometry Images" (SPM 2005): §4.2.1 (initial synthesis), §4.2.2 (boundary
//! resynthesis) and the synthesis side of §4.3 (discretized orientation and scaling). The
//! oriented and scaled sample set, its pyramids, features and kd-trees come from
//! [`crate::analyse_exemplar::texel_variants`].
//!
//! A geometry image of side `n = 2^k + 1` has `(n − 1) / 2^l + 1` samples per side at pyramid
//! level `l`; sample `i` of level `l` is sample `i · 2^l` of level 0, and its field values are
//! that sample's. Coarse to fine, each level is
//! 1. started: the coarsest level with texels drawn at random from the sample (the variant each
//!    texel would be matched in, so the start has the sample's statistics), each finer level
//!    with the finished coarser level, interpolated;
//! 2. synthesized in scanline order with the causal Γ template, plus the full neighbourhood one
//!    level coarser above the coarsest level. Each texel is matched in one variant (§4.3): of
//!    the two discretized orientations next to the field angle, each with probability by
//!    closeness, and of the two scales next to `level = log2 R + 2` (clamped to the range of
//!    scales), `T_s` with probability `s + 1 − level`. The nearest candidate in that variant
//!    (PCA-reduced features, kd-tree search within `1 + search_eps`) gives the texel: the
//!    variant's texel, whose `(dx, dy)` the analysis already turned into the variant's axes,
//!    which are the grid's;
//! 3. resynthesized near the cuts (§4.2.2), `boundary_passes` times: texels within
//!    `boundary_strip` texels of a side sample that has a mate, in scanline order, with the full
//!    template, which reads both sides of the cut (below). After each pass (and after step 2)
//!    each mate group takes the value of one member, chosen by a counter-based hash, so mated
//!    texels end bit-identical.
//!
//! Reading across a cut: the square's sides are taken in perimeter order (top `i = 0` with
//! `j` increasing, right, bottom, left), each with a tangent `t` along that order and an
//! inward normal `m`. A tap `b` texels outside side sample `p` is read at `q + b · m_q`, where
//! `q` is a mate of `p` whose side runs the opposite way along the cut: the pairing `(p, side)`
//! ↔ `(q, side)` is accepted when the border neighbours agree (`p ± t_p` is mated with
//! `q ∓ t_q`), which also tells which side of a corner sample is meant. The value is turned by
//! the quarter turn between the two sides' grid axes.
//!
//! Frames: while synthesizing, every texel's `(dx, dy)` are in its own side's grid axes
//! (`x` = column `j`, `y` = row `i`, as the local frames of
//! [`crate::geom::geometry_image::local_frames`] are away from the cuts). Those frames give a
//! mated sample its group representative's frame, so in the output every member of a mate group
//! holds the representative-frame value, turned by the quarter turn between the member's and
//! the representative's sides; all members' output texels are bit-identical.
//!
//! Surface metric (`anisotropic`, the default): the paper's templates are laid out
//! in grid texels and its scale `R` is one number per sample, so where the geometry image
//! stretches the surface more one way than the other (long thin parts) the relief came out as
//! streaks. Each texel instead reads template tap `s` (in sample texels) at grid offset
//! `round(A⁻¹ s)` and shifts a coherent candidate by `A o` for a neighbour `o` grid steps away,
//! with `A` the unimodular square root of the grid's metric ([`SurfaceMetric`]); a finer level's
//! start takes its parent's source shifted by `A` times the child's offset; `R` uses the
//! metric's isotropic spacing; and the field's direction goes through `A` into sample axes. The
//! variants stay isotropic. In the scanline pass a tap so placed can fall outside the causal
//! half: taps not finished in both the scanline and the wave order are read from the level's
//! starting values, which keeps the wave order exact.
//!
//! Heuristics (the paper: "for other problem cases, e.g. texels in the corner of geometry images,
//! or where two cuts meet, we use a heuristic approach"):
//! - A tap outside the square across a corner (outside in both `i` and `j`) is first mirrored
//!   back along the axis it overshoots less (rows on ties), then read across the other side.
//! - A tap across a side sample without a mate, or whose pairing cannot be confirmed, is
//!   mirrored into the square. A tap mapped across a cut that falls outside the square again is
//!   mirrored.
//! - A mate whose pairing with its group representative cannot be confirmed directly (e.g. the
//!   third member where cuts meet) is taken to share the representative's axes.
//! - Mate groups at a coarse level are those of the level-0 samples `(i · 2^l, j · 2^l)`
//!   restricted to that lattice (the parameterization puts cut nodes on the coarsest grid).
//!
//! Departures and choices the paper leaves open:
//! - The boundary template's size is a parameter of the variant set
//!   (`TexelVariantParams::boundary_template`), whose analysis builds its features and trees,
//!   not of this stage.
//! - The scanline pass reads taps outside the square (across cuts, or mirrored) from the level's
//!   starting values, not from texels synthesized in this pass. The paper "ignores the
//!   boundary" there; reading the synthesized texels instead (mirrored) fed each border
//!   texel's choice back into its neighbours' templates and grew repeating diagonal streaks from
//!   the left border on the test bumps. Starting finer levels from the coarser result (rather
//!   than from the pyramid of the random start, whose blurred noise has almost no contrast)
//!   gives those taps a sensible prediction, across cuts too.
//! - Scanline order is kept exactly, but texels on one anti-diagonal wave (`j + (r + 1) i`
//!   constant, `r` the template radius) do not depend on one another, so each wave is computed
//!   in parallel: the result is the sequential one (a unit test compares them), for any number
//!   of threads. Boundary passes are sequential.
//! - The random number that picks the scale is shared by the texels of a cell of a jittered
//!   grid of template spacing (each texel takes the cell whose jittered centre is nearest); the
//!   probabilities per texel are the paper's. Drawn per texel, neighbouring texels matched at
//!   different scales and the texture turned into grain where `R` falls between two scales.
//!   Orientations are still drawn per texel: per cell, stripes broke into straight pieces at the
//!   cell borders.
//!
//! [`SurfaceMetric`]: crate::synthesize::surface_metric::SurfaceMetric

mod appearance_synthesis;
mod controls;
mod grid;
mod level;
mod matching;
mod params;
mod run;

pub use appearance_synthesis::synthesize_appearance;
pub use controls::{TexelControls, sample_frame_maps, texel_controls};
pub use params::{
    GeometrySynthParams, GeometryTextureError, ScaleChoice, Search, SynthAlgorithm, Taps,
};
pub use run::synthesize_geometry_texture;

/// The `geometry_texture` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("geometry_texture", 7);

/// The per-sample controls of synthesis (§4.3), computed by the field stage.
pub use crate::field::param_field::ParamField;

/// The synthesize node: the geometric texture over the geometry image. `appearance` is the
/// analysis the appearance synthesizer reads (`None` for the template synthesizer).
pub fn node(
    gi: &crate::geom::geometry_image::GeometryImage,
    field: &ParamField,
    variants: &crate::analyse_exemplar::texel_variants::TexelVariantsRef<'_>,
    appearance: Option<&crate::analyse_exemplar::appearance_space::AppearanceSpaceRef<'_>>,
    p: &GeometrySynthParams,
    progress: &dyn Fn(f32),
) -> Result<crate::geom::geometry_image::TexelImage, texsyn_core::algorithm::Failure> {
    use texsyn_core::algorithm::Failure;
    if field.dir.len() != gi.positions.len() {
        return Err(Failure::internal(
            "field and geometry image disagree on the sample count",
        ));
    }
    match (p.algorithm, appearance) {
        (SynthAlgorithm::Template, _) => {
            synthesize_geometry_texture(gi, field, variants, p, progress)
        }
        (SynthAlgorithm::Appearance, Some(space)) => {
            synthesize_appearance(gi, field, variants, space, p, progress)
        }
        (SynthAlgorithm::Appearance, None) => {
            return Err(Failure::internal(
                "the appearance synthesizer was planned without its appearance space",
            ));
        }
    }
    .map_err(Failure::input)
}
