//! The synthesis' parameters (templates, scale choice, search, boundary passes), their
//! validation, its errors, and the check that the geometry image, the field and the variants'
//! pyramid fit together.

use super::ParamField;
use crate::check::{ParamError, check_range};
use crate::geom::geometry_image::GeometryImage;
use crate::synthesize::surface_metric::MAX_STRETCH;
use glam::Vec2;
use serde::{Deserialize, Serialize};

/// Parameters of the synthesis.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GeometrySynthParams {
    /// Which synthesizer fills the geometry image: `"template"` (Lai et al.'s Γ-template
    /// scanline synthesis of texel values, the module docs) or `"appearance"` (parallel
    /// synthesis of sample coordinates in appearance space, Lefebvre & Hoppe 2005/2006, see
    /// [`super::appearance_synthesis`]). Default: `"appearance"`, which meets more of the
    /// quality goals on the shipped configs (README, "Geometry images: which synthesizer").
    pub algorithm: SynthAlgorithm,
    /// `appearance` only: correction passes per level, 1..=8, each of 4 sub-passes (Lefebvre &
    /// Hoppe 2005 §3.2); the coarsest level runs twice as many. Default: 8 (on the flat
    /// sheet of `tests/it/gi_sheet_quality.rs`, ratio 0.78 / 0.68 / 0.65 at 2 / 4 / 8 passes
    /// with 4 candidates per set and no occurrence penalty, and the seams between the coarse
    /// levels' blocks still show at 2).
    pub appearance_passes: u32,
    /// `appearance` only: entries of each k-coherence candidate set (the texel itself and
    /// `k − 1` similar ones), 1..=8. Default: 8 (against 4, both without the occurrence
    /// penalty: the crack network of `appearance_synthesis.rs`'s tests breaks into 4.0
    /// components on average over 5 seeds instead of 8.4; the shipped dragons' ratios come
    /// 0.009 and 0.018 nearer their floors, for 0.049 and 0.083 of their gradient ratios, and
    /// the cow's moves 0.007 away; synthesis takes 1.4 s instead of 0.8 s at 257², measured
    /// in one session).
    pub appearance_k: u32,
    /// `appearance` only: how much better (a factor `1 + appearance_coherence` on the
    /// neighbourhood distance) a candidate that continues no neighbour's run must match than
    /// one that does, 0..=10. Default: 0.1 (at 1, the coarse levels' square blocks survive to
    /// the finest level as straight seams).
    pub appearance_coherence: f32,
    /// `appearance` only: weight of the occurrence penalty (Kopf et al. 2007 §3.3): a
    /// candidate whose block of the sample (one stack spacing square) is already copied more
    /// than its fair share pays the factor `1 + weight · (use / share − 1)`, 0..=10. Default
    /// 1; against 0, over 12 seeds the crack network of `appearance_synthesis.rs`'s tests
    /// breaks into a median of 3 components instead of 5; at density offset 0 relief_cow
    /// scores 0.888 / 0.605 / 0.861 instead of 0.971 / 0.545 / 0.783 and dragon_knot 0.753 /
    /// 0.604 / 0.966 instead of 0.805 / 0.573 / 1.077; the undistorted square sheet of
    /// `tests/it/gi_sheet_quality.rs` loses (0.539 against 0.461: more seams, where nothing
    /// else rewards spreading). At 2 the shapes score about the same, the square 0.569, and
    /// the rhombus keeps its gradient goal by 0.002 only.
    pub appearance_occupancy: f32,
    /// `appearance` only: jitter amplitude per level, in units of the level's stack spacing,
    /// rounded to whole texels, 0..=2 (Lefebvre & Hoppe 2005 §3.1, their `r`). Default: 0 (the
    /// random start at the coarsest level already gives the variety; 0.3 scored 0.05–0.06
    /// worse on the flat sheet).
    pub jitter: f32,
    /// Seed of every random choice (start texels, variant choices, mate propagation).
    /// Default: 0.
    pub seed: u64,
    /// Boundary resynthesis passes per level, 0..=16 (§4.2.2: "can be repeatedly performed
    /// several times"). Default: 2.
    pub boundary_passes: u32,
    /// Width in texels (of each level) of the strip along mated sides that boundary
    /// resynthesis redoes, 1..=64. Default: 4.
    pub boundary_strip: u32,
    /// Approximate nearest-neighbour factor, 0..=10: a match may be up to `1 + search_eps`
    /// times farther than the best one; 0 = exact. Default: 0.25 (on the tests' bumps, 0.5 and
    /// 1 left flat triangular plateaus that exact search does not; 0.25 looked like exact
    /// search, and at 257² exact search costs about 0.25 s on 2 cores anyway). Used by
    /// `search = "per_texel"` only.
    pub search_eps: f32,
    /// How a texel's match is found: `"k_coherence"` (default) or `"per_texel"` (the paper's
    /// kd-tree search over every texel of the variant, §4.2.1).
    pub search: Search,
    /// How much better (as a factor `1 + coherence` on the template distance) a k-coherent
    /// candidate must match than the best shifted one to be taken (`k_coherence` only),
    /// 0..=10. Default: see [`GeometrySynthParams::default`].
    pub coherence: f32,
    /// Correction passes per level after the scanline pass (`k_coherence` only; Lefebvre &
    /// Hoppe 2005), 0..=8: every texel rematched with the full boundary template against the
    /// level as the previous pass left it, all at once. Default: 1.
    pub correction_passes: u32,
    /// Factor on the coarser level's taps in the template distance of `k_coherence`, 0..=4
    /// (`per_texel` uses `analyse_exemplar.coarse_weight`, which its features are built with).
    /// Default: 1 (relief_cow at `analyse_exemplar.scales = 1`, density offset 0, coherence 1,
    /// one correction pass: nearest-patch ratio 0.650, against 0.815 for `per_texel`; measured
    /// with `examples/gi_quality.rs`).
    pub coarse_weight: f32,
    /// Whether the templates are laid out in the surface's metric (see [`SurfaceMetric`]):
    /// each texel's taps and coherent shifts go through the geometry image's Jacobian, so
    /// relief keeps its shape where the grid stretches the surface more one way than the other
    /// (long thin parts: legs, necks, trunks). `false` is the paper's template in grid texels,
    /// which draws the relief out into streaks there. Default: true.
    ///
    /// [`SurfaceMetric`]: crate::synthesize::surface_metric::SurfaceMetric
    pub anisotropic: bool,
    /// With the surface metric, how a template tap that falls between grid points is read:
    /// `"bilinear"` (default) or `"nearest"` (the grid point nearest to it, as the coherent
    /// shifts round).
    pub taps: Taps,
    /// How a texel's scale is picked between the two variants' scales next to its
    /// `log2 R + middle`: `"random"` (default; the paper's, `T_s` with probability by
    /// closeness, shared over jittered cells) or `"nearest"` (the closer one everywhere).
    pub scale_choice: ScaleChoice,
    /// With the surface metric, whether a texel takes the value at its source's sub-texel
    /// position (bilinear between the four variant texels around it) rather than the nearest
    /// texel's. Coherent runs then follow the fractional shifts `A o` in value too, instead of
    /// repeating a texel where a grid step is less than one sample texel. Default: false.
    pub subtexel: bool,
    /// With the surface metric, the largest stretch `λ` undone, 1..=4 (see [`SurfaceMetric`]):
    /// where a grid step one way spans more than `λ²` times the surface length of a step the
    /// other way, the rest
    /// is left to the grid. A grid step along the stretched direction covers `λ` times the
    /// isotropic spacing, and relief finer than that is lost there. Default: 4.
    ///
    /// [`SurfaceMetric`]: crate::synthesize::surface_metric::SurfaceMetric
    pub max_stretch: f32,
}

/// How template taps between grid points are read (see [`GeometrySynthParams::taps`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Taps {
    #[default]
    Bilinear,
    Nearest,
}

/// How each texel's scale is picked (see [`GeometrySynthParams::scale_choice`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ScaleChoice {
    #[default]
    Random,
    Nearest,
}

/// The synthesizer of a geometry image.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SynthAlgorithm {
    /// Lai et al.'s Γ-template scanline synthesis of texel values (§4.2).
    Template,
    /// Parallel synthesis of sample coordinates in appearance space (Lefebvre & Hoppe).
    #[default]
    Appearance,
}

/// The candidate search of each texel's match.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Search {
    /// Coherent candidates (Ashikhmin 2001) and their k-coherent sets (Tong et al. 2002),
    /// compared by the full template distance.
    #[default]
    KCoherence,
    /// The paper's approximate nearest neighbour over all texels of the variant.
    PerTexel,
}

impl Default for GeometrySynthParams {
    fn default() -> Self {
        GeometrySynthParams {
            algorithm: SynthAlgorithm::Appearance,
            appearance_passes: 8,
            appearance_k: 8,
            appearance_coherence: 0.1,
            appearance_occupancy: 1.0,
            jitter: 0.0,
            seed: 0,
            boundary_passes: 2,
            boundary_strip: 4,
            search_eps: 0.25,
            search: Search::KCoherence,
            coherence: 1.0,
            correction_passes: 1,
            coarse_weight: 1.0,
            anisotropic: true,
            taps: Taps::Bilinear,
            scale_choice: ScaleChoice::Random,
            subtexel: false,
            max_stretch: MAX_STRETCH as f32,
        }
    }
}

impl GeometrySynthParams {
    /// Checks every field; the error names the field, its range and the value.
    pub fn validate(&self) -> Result<(), ParamError> {
        let within = |e: ParamError| e.within("geometry texture");
        check_range("boundary_passes", self.boundary_passes, 0, 16).map_err(within)?;
        check_range("appearance_passes", self.appearance_passes, 1, 8).map_err(within)?;
        check_range("appearance_k", self.appearance_k, 1, 8).map_err(within)?;
        check_range("appearance_coherence", self.appearance_coherence, 0.0, 10.0)
            .map_err(within)?;
        check_range("appearance_occupancy", self.appearance_occupancy, 0.0, 10.0)
            .map_err(within)?;
        check_range("jitter", self.jitter, 0.0, 2.0).map_err(within)?;
        check_range("boundary_strip", self.boundary_strip, 1, 64).map_err(within)?;
        check_range("search_eps", self.search_eps, 0.0, 10.0).map_err(within)?;
        check_range("coherence", self.coherence, 0.0, 10.0).map_err(within)?;
        check_range("correction_passes", self.correction_passes, 0, 8).map_err(within)?;
        check_range("coarse_weight", self.coarse_weight, 0.0, 4.0).map_err(within)?;
        check_range("max_stretch", self.max_stretch, 1.0, MAX_STRETCH as f32).map_err(within)
    }
}

/// Why a geometry texture could not be synthesized: bad parameters, or inputs that disagree
/// with each other.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GeometryTextureError {
    #[error(transparent)]
    Params(#[from] ParamError),
    #[error(
        "geometry texture: a geometry image of side {n} cannot have {levels} pyramid levels: \
         the side must be 2^{} · k + 1 with k ≥ 2 (e.g. {}, {} or {})",
        .levels - 1,
        2 * (1usize << (.levels - 1)) + 1,
        4 * (1usize << (.levels - 1)) + 1,
        8 * (1usize << (.levels - 1)) + 1
    )]
    Levels { n: usize, levels: usize },
    #[error(
        "geometry texture: search = \"per_texel\" needs the variants' per-texel search \
         structures, which this variant set was built without"
    )]
    NoPerTexelSets,
    #[error(
        "geometry texture: the template synthesizer needs the sample's k-coherent sets, which \
         this variant set was built without"
    )]
    NoCoherentSets,
    #[error(
        "geometry texture: the appearance space has {channels} channels and {k}-entry candidate \
         sets, which disagree with the variants' channels or synthesize.appearance_k"
    )]
    AppearanceSpace { channels: u32, k: u32 },
    #[error("geometry texture: the geometry image has {entries} mate entries for {n}×{n} samples")]
    MateCount { entries: usize, n: usize },
    #[error(
        "geometry texture: sample {sample}'s mate representative {rep} is not a representative"
    )]
    MateRep { sample: usize, rep: u32 },
    #[error(
        "geometry texture: the field has {dirs} directions and {scales} scales for {samples} samples"
    )]
    FieldSize {
        dirs: usize,
        scales: usize,
        samples: usize,
    },
    #[error("geometry texture: field direction at sample ({i}, {j}) is not finite: {dir}")]
    FieldDirection { i: usize, j: usize, dir: Vec2 },
    #[error(
        "geometry texture: relative scale at sample ({i}, {j}) must be a positive number, got {scale}"
    )]
    FieldScale { i: usize, j: usize, scale: f32 },
}

pub(super) fn check_inputs(
    gi: &GeometryImage,
    field: &ParamField,
    levels: usize,
) -> Result<(), GeometryTextureError> {
    use GeometryTextureError as E;
    let n = gi.n as usize;
    let nn = n * n;
    let step = 1usize << (levels - 1);
    if n < 3 || !(n - 1).is_multiple_of(step) || (n - 1) / step < 2 {
        return Err(E::Levels { n, levels });
    }
    if gi.mate_rep.len() != nn {
        return Err(E::MateCount {
            entries: gi.mate_rep.len(),
            n,
        });
    }
    for (k, &r) in gi.mate_rep.iter().enumerate() {
        if r as usize >= nn || gi.mate_rep[r as usize] != r {
            return Err(E::MateRep { sample: k, rep: r });
        }
    }
    if field.dir.len() != nn || field.rel_scale.len() != nn {
        return Err(E::FieldSize {
            dirs: field.dir.len(),
            scales: field.rel_scale.len(),
            samples: nn,
        });
    }
    if let Some(k) = field.dir.iter().position(|d| !d.is_finite()) {
        return Err(E::FieldDirection {
            i: k / n,
            j: k % n,
            dir: field.dir[k],
        });
    }
    if let Some(k) = field
        .rel_scale
        .iter()
        .position(|r| !(r.is_finite() && *r > 0.0))
    {
        return Err(E::FieldScale {
            i: k / n,
            j: k % n,
            scale: field.rel_scale[k],
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn params_validate_names_the_field() {
        assert!(GeometrySynthParams::default().validate().is_ok());
        for (p, name) in [
            (
                GeometrySynthParams {
                    boundary_strip: 0,
                    ..Default::default()
                },
                "boundary_strip",
            ),
            (
                GeometrySynthParams {
                    search_eps: -1.0,
                    ..Default::default()
                },
                "search_eps",
            ),
            (
                GeometrySynthParams {
                    boundary_passes: 17,
                    ..Default::default()
                },
                "boundary_passes",
            ),
        ] {
            let e = p.validate().unwrap_err().to_string();
            assert!(e.contains(name), "{e}");
        }
        let e: Result<GeometrySynthParams, _> = toml::from_str("boundary_pass = 2");
        assert!(e.is_err());
    }
}
