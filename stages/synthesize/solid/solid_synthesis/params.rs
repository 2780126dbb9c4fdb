//! The synthesis' parameters and errors: the pyramid over the volume, per-level settings
//! (passes, scheme, sampling, jitter), their validation, and how the pyramid depth is shared
//! with the analysis.

use crate::check::ParamError;
use crate::parameterize::volume_embedding::Volume;
use glam::{IVec3, Vec3};
use serde::{Deserialize, Serialize};

/// The solid's pyramid: its finest level is the voxel grid of the volume embedding, and it
/// has `levels` levels. Serialized, it is the grid's origin, voxel side and dims, then the
/// level count: what a brick depends on of the volume.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Pyramid {
    pub volume: Volume,
    /// Pyramid levels L (the analysis's, and one [`LevelParams`] each).
    pub levels: u32,
}

impl Pyramid {
    /// Finest voxels per voxel of `level`: `2^(L−level)`.
    pub fn step(&self, level: u32) -> i32 {
        1 << (self.levels - level)
    }

    /// The domain `[0, dims)` of `level`.
    pub fn level_dims(&self, level: u32) -> IVec3 {
        let s = self.step(level) as u32;
        let d = self.volume.dims;
        IVec3::new(
            d[0].div_ceil(s) as i32,
            d[1].div_ceil(s) as i32,
            d[2].div_ceil(s) as i32,
        )
    }

    /// Object-space position of the (fractional) voxel coordinates `x` of `level`.
    pub fn position_f(&self, level: u32, x: Vec3) -> Vec3 {
        Vec3::from(self.volume.origin) + (x * self.step(level) as f32 + 0.5) * self.volume.voxel
    }

    /// Object-space position of voxel `v` of `level`.
    pub fn position(&self, level: u32, v: IVec3) -> Vec3 {
        Vec3::from(self.volume.origin)
            + ((v * self.step(level)).as_vec3() + 0.5) * self.volume.voxel
    }

    pub(super) fn validate(&self) -> Result<(), SolidError> {
        let v = &self.volume;
        let ok = Vec3::from(v.origin).is_finite()
            && v.voxel.is_finite()
            && v.voxel > 0.0
            && v.dims.iter().all(|&d| (1..=65536).contains(&d));
        check(
            "volume",
            v,
            ok,
            "expected a finite origin, voxel > 0 and 1..=65536 voxels per side",
        )?;
        check(
            "synthesize.levels",
            self.levels,
            (1..=8).contains(&self.levels),
            "expected 1..=8 levels, one entry each",
        )
    }
}

/// How a level corrects.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Scheme {
    /// No barriers (the standard scheme of Lefebvre & Hoppe and Dong et al.).
    Plain,
    /// Every pass behind the `M`-cell barriers.
    Grid,
    /// `⌈P/2⌉` grid passes, then `⌊P/2⌋` dual-grid passes (§5.3).
    DualGrid,
}

/// The colour a voxel shows in the plane neighbourhoods that matching gathers (§4.3 gathers
/// "the color of voxels"; what that colour is, for a voxel holding three texels, is the
/// choice here).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NeighbourhoodColour {
    /// In the neighbourhood of plane `P` a voxel shows its own texel in `P`'s exemplar: each
    /// plane is compared with what a cut along it shows (a departure, see the module docs).
    Plane,
    /// Every neighbourhood shows the plane-weighted mean of the voxel's three texels.
    Mean,
}

/// Parameters of one level.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LevelParams {
    /// Correction passes P, 0..=30. Default: 2.
    pub passes: u32,
    /// Default: dual-grid.
    pub scheme: Scheme,
    /// `s³ = 8` subpasses per pass. Default: true.
    pub subpasses: bool,
    /// Trilinear neighbourhood sampling (else nearest voxel). Default: false.
    pub trilinear: bool,
    /// Upsampling jitter in units of `h_l`, 0..=4. Default: 0.
    pub jitter: f32,
}

impl Default for LevelParams {
    fn default() -> Self {
        LevelParams {
            passes: 2,
            scheme: Scheme::DualGrid,
            subpasses: true,
            trilinear: false,
            jitter: 0.0,
        }
    }
}

/// Synthesis parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SolidParams {
    /// Seed of the counter-based randomness (slab offsets, jitter). Default: 0.
    pub seed: u64,
    /// Cell side M of grid and dual-grid correction, and brick side; even, 4..=64.
    /// Default: 12 (§5.3.2: M = 10–15).
    pub cell: u32,
    /// Side K of the initialization subparts, in coarsest-level voxels, 1..=4096. Default: 32.
    pub subpart: u32,
    /// Also offer, for each neighbour `w` gathered for `S(v)`, its whole triple shifted back
    /// to `v` (eq. 4), not only the candidates of the shifted pixel (a departure, see the
    /// module docs). Default: true.
    pub coherent_candidates: bool,
    /// Per level, coarsest first; as many as the pyramid has levels. Default:
    /// [`SolidParams::paper`] with 4 levels.
    pub levels: Vec<LevelParams>,
    /// §6 "in coarser levels, the field is further smoothed": on the [coarse
    /// levels](coarse_level), the field smoothed by a Gaussian of σ = `field_smoothing` voxels
    /// of the level (`stages/field/coarse_field_smoothing.rs`), 0..=16. Default: 0 (off).
    /// Serialized only when on, so keys without it do not change.
    #[serde(skip_serializing_if = "is_zero")]
    pub field_smoothing: f32,
    /// §4.3 "for coarse levels, a numerical integration along the directions is used": on the
    /// [coarse levels](coarse_level), neighbourhoods are sampled along the field's integral
    /// lines instead of the centre voxel's frame (`field_integration.rs`). Default: false.
    /// Serialized only when on.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub field_integration: bool,
    /// What a voxel shows in the neighbourhoods matching gathers. Default: `plane`.
    pub neighbourhood_colour: NeighbourhoodColour,
}

fn is_zero(x: &f32) -> bool {
    *x == 0.0
}

/// The paper's "coarse levels" (§4.3, §6), where trilinear sampling, field smoothing and
/// integration along the field apply: the coarser half of the pyramid, `2·li < L` for array
/// level `li` (levels 1–2 of 4).
pub fn coarse_level(li: usize, levels: usize) -> bool {
    2 * li < levels
}

impl Default for SolidParams {
    fn default() -> Self {
        SolidParams::paper(4)
    }
}

impl SolidParams {
    /// The paper's settings (§6): 4 plain passes on the coarsest level, 2 dual-grid passes
    /// (one grid, one dual) above, 8 subpasses everywhere; trilinear sampling on the coarser
    /// half of the levels, nearest above.
    pub fn paper(levels: u32) -> SolidParams {
        let levels = (0..levels)
            .map(|li| LevelParams {
                passes: if li == 0 { 4 } else { 2 },
                scheme: if li == 0 {
                    Scheme::Plain
                } else {
                    Scheme::DualGrid
                },
                subpasses: true,
                trilinear: coarse_level(li as usize, levels as usize),
                jitter: 0.0,
            })
            .collect();
        SolidParams {
            seed: 0,
            cell: 12,
            subpart: 32,
            coherent_candidates: true,
            levels,
            field_smoothing: 0.0,
            field_integration: false,
            neighbourhood_colour: NeighbourhoodColour::Plane,
        }
    }

    /// The same with one scheme on every level above the coarsest (e.g. [`Scheme::Plain`]
    /// for the standard scheme the paper compares with).
    pub fn with_scheme(mut self, scheme: Scheme) -> SolidParams {
        for l in self.levels.iter_mut().skip(1) {
            l.scheme = scheme;
        }
        self
    }

    /// Checks every setting (the method calls it when the config is read, so a bad value is
    /// reported before anything runs).
    pub fn validate(&self) -> Result<(), SolidError> {
        check(
            "synthesize.cell",
            self.cell,
            (4..=64).contains(&self.cell) && self.cell.is_multiple_of(2),
            "expected an even number in 4..=64",
        )?;
        check(
            "synthesize.subpart",
            self.subpart,
            (1..=4096).contains(&self.subpart),
            "expected 1..=4096",
        )?;
        check(
            "synthesize.field_smoothing",
            self.field_smoothing,
            self.field_smoothing.is_finite() && (0.0..=16.0).contains(&self.field_smoothing),
            "expected 0..=16 (voxels of the level; 0 = off)",
        )?;
        for l in &self.levels {
            check(
                "synthesize.levels[].passes",
                l.passes,
                l.passes <= 30,
                "expected 0..=30",
            )?;
            check(
                "synthesize.levels[].jitter",
                l.jitter,
                l.jitter.is_finite() && (0.0..=4.0).contains(&l.jitter),
                "expected 0..=4",
            )?;
        }
        Ok(())
    }
}

/// The pyramid depth is one choice made in two places: the analysis' `depth`
/// (`analyse_exemplar.levels`) and one [`LevelParams`] per level (`[[synthesize.levels]]`).
/// Whichever a config gives (`given`: the depth, the levels) sets the other, each level
/// getting the [paper's settings](SolidParams::paper) when only the depth is given; given
/// both, they must agree.
pub fn couple_levels(
    depth: &mut u32,
    levels: &mut Vec<LevelParams>,
    given: [bool; 2],
) -> Result<(), ParamError> {
    let n = levels.len();
    let message = match (given[0], given[1]) {
        (true, true) if n != *depth as usize => format!(
            "has {n} entries but analyse_exemplar.levels is {depth}: give one \
             [[synthesize.levels]] per pyramid level, or leave one of the two out to derive it"
        ),
        (false, true) if !(1..=8).contains(&n) => {
            format!("has {n} entries: expected 1..=8, one per pyramid level")
        }
        (true, true) => return Ok(()),
        (false, true) => {
            *depth = n as u32;
            return Ok(());
        }
        // A depth out of range is the analysis parameters' error.
        (_, false) => {
            *levels = SolidParams::paper((*depth).min(8)).levels;
            return Ok(());
        }
    };
    Err(ParamError::invalid("synthesize.levels", message))
}

/// What went wrong; parameter errors name the parameter.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SolidError {
    #[error("{name} = {value}: {expected}")]
    Param {
        name: String,
        value: String,
        expected: String,
    },
    #[error(
        "the analysis has {analysis} levels and the synthesis parameters {params}; they must agree"
    )]
    Levels { analysis: u32, params: u32 },
    #[error("rotation field: {0}")]
    Field(String),
    #[error("brick {brick:?} of level {level} vanished from the brick store during synthesis")]
    MissingBrick { level: u32, brick: [i32; 3] },
    #[error("brick: {0}")]
    Brick(String),
    #[error("voxel {voxel:?} was requested but not synthesized (a bug in texsyn)")]
    NotSynthesized { voxel: [i32; 3] },
}

impl SolidError {
    /// Whether texsyn is at fault (artifacts that disagree, a brick store that lost a brick),
    /// not the user's parameters or exemplars.
    pub fn is_internal(&self) -> bool {
        matches!(
            self,
            SolidError::Levels { .. }
                | SolidError::MissingBrick { .. }
                | SolidError::Brick(_)
                | SolidError::NotSynthesized { .. }
        )
    }
}

fn check<T: std::fmt::Debug>(
    name: &str,
    value: T,
    ok: bool,
    expected: &str,
) -> Result<(), SolidError> {
    if ok {
        Ok(())
    } else {
        Err(SolidError::Param {
            name: name.to_owned(),
            value: format!("{value:?}"),
            expected: expected.to_owned(),
        })
    }
}
