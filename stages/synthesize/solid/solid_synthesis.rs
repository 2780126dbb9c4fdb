//! Deterministic, on-demand solid texture synthesis guided by a rotation field (Zhang, Du,
//! Lai, Ni & Hu, "Sketch guided solid texturing", §4–§5), on the parallel synthesis scheme of
//! Lefebvre & Hoppe 2005 with the candidate triples of Dong et al. 2008
//! (`stages/analyse_exemplar/candidate_triples.rs`).
//!
//! # The pyramid
//!
//! A [`Pyramid`] over the embedding's [`Volume`] has `L` levels numbered `1..=L` (level `L`
//! finest, the volume's own grid). Level `l`'s voxel `v` (integer coordinates, domain
//! `[0, ⌈dims / 2^(L−l)⌉)`) sits at finest voxel `v·2^(L−l)`, whose centre is
//! `origin + (v·2^(L−l) + ½)·voxel` in object space; its parent is
//! `⌊v/2⌋`. Each voxel holds a coordinate [`Triple`]; one level-`l` voxel step is
//! `h_l = 2^(L−l)` exemplar pixels (divided by the field's scale). Reads outside the domain
//! clamp to it (the paper embeds the object in a larger volume for the same reason).
//!
//! # Per level (§4)
//!
//! - **Initialization** (§4.1, level 1): space is tiled with candidate slabs in the local
//!   frame: local voxel `u` gets `S((o + h·(u_x, u_y)) mod (W, H)) + h·(0, 0, u_z − kD − ⌊D/2⌋)`
//!   for the slab `k = ⌊u_z / D⌋` it lies in; `S` are the analysis's slab seeds. A voxel `v`
//!   with frame `q_v` in the `K × K × K` subpart with centre `c` takes the slab triple at
//!   `[c + q_v⁻¹ (v − c) / s]` (`T([q_v⁻¹ v])` rotated about each subpart's centre, so
//!   distortion stays local). The slabs of a subpart share one xy offset `o`, a counter-based
//!   hash of `(seed, subpart)`: a slab boundary then only restarts the yz and zx coordinates and
//!   keeps the xy layer. (A random offset per slab made boundaries that correction could not
//!   repair: on a layered exemplar, every slab kept its own stripe phase.)
//! - **Upsampling** (§4.2, eq. 3–4): `T(v) = T(v_p) + [q_{v_p}⁻¹ t_v / s]` with
//!   `t_v = h_l (v mod 2)`, plus optional jitter `h_l·jitter·(u − ½)` per axis (Lefebvre &
//!   Hoppe's multiresolution jitter, `u` counter-based).
//! - **Correction** (§4.3): the three `N × N` neighbourhoods `v + s q_v (i, j, 0)` etc., aligned
//!   with the local frame, are gathered from the level's voxel colours (trilinear or nearest,
//!   per level), each projected on its plane's PCA basis, and compared with the candidates
//!   `S(v)` in the reduced form: for plane `P` and `d ∈ {−1, 0, 1}²` in `P`, the voxel
//!   `w = [v + s q_v d]` and its coordinate `T_P(w)` shifted back by `w`'s exemplar offset
//!   `h_l P(q_v⁻¹ (w − v) / s)` names an exemplar pixel whose `k` candidate triples join the
//!   set. The candidate with the least plane-weighted squared distance in PCA space wins
//!   (ties: the first visited, planes xy, yz, zx, then `d` row by row). A voxel's colour is
//!   the plane-weighted mean of its triple's three stack texels at the level (the plain
//!   average by default); planes of weight 0 are neither gathered nor matched.
//! - **Subpasses and barriers** (§4.3.1, §5.2–5.3): a level's corrections are a [`Schedule`] of
//!   stages and steps with [`HistoryWindow`]s (`history_window.rs`): plain correction, grid
//!   correction (barriers at the `M`-cells) or dual-grid correction (`⌈P/2⌉` grid passes then
//!   `⌊P/2⌋` passes behind the dual lattice, offset `M/2`).
//!
//! # On demand, in bricks
//!
//! Each level is stored as bricks of `M³` voxels — exactly the dual-grid cells: brick `b`
//! covers `[bM + ⌊M/2⌋, (b+1)M + ⌊M/2⌋)`. A request (finest voxels) names the finest bricks it
//! touches; for the missing ones, `dependent_set.rs` works backwards through the level's
//! schedule to the exact set of voxel versions they depend on, whose upsampling names the
//! bricks needed one level down, and so on to level 1 ([`SolidSynthesis::bricks_needed`]).
//! Then each level is computed from the bottom: only the missing bricks' dependent set, from
//! the parents' bricks in the store.
//!
//! Why caching is sound: a brick's triples are the values a synthesis of the whole domain
//! would give them, because the versions computed for it form a dependency-closed set (every
//! version read is itself computed, from the same inputs, by the same pure function of the
//! triples it reads, the analysis, the field and the seed), and all randomness is a
//! counter-based hash of voxel coordinates. So a brick is a pure function of its coordinates
//! and the inputs, never of the request or of the thread count (parallel loops only map
//! disjoint voxels and commit in a fixed order). Aligning bricks with the dual cells is what
//! makes them cheap: with dual-grid correction a brick depends on its own cell's history and
//! on the grid-stage result within the reach `r` of it, i.e. on at most the 8 (27 if `r ≥
//! M/2`) grid cells around it, and through them on a bounded block of parents (`M + r` voxels
//! across at the level below), independently of the pass count.
//!
//! # Departures
//!
//! - Matching uses squared L2 in PCA space (the paper: L1 on RGB); see the analysis.
//! - `S(v)` also holds, for each neighbour `w` it visits, `w`'s whole triple shifted back to `v`
//!   (`T(w) + [−h q_v⁻¹ (w − v) / s]`, eq. 4), as k-coherence does in 2D (option
//!   `coherent_candidates`, default on). Without it, every correction replaces all three
//!   coordinates by those of a listed triple, and the planes other than the one the candidate
//!   came from lose their coherence: on wood2, stripes broke up into short pieces.
//! - On coarse levels the paper integrates the field along the neighbourhood's directions
//!   (§4.3); here that is the switch `field_integration` (default off: every level samples with
//!   the centre voxel's frame, the paper's fine-level choice; `field_integration.rs`), and the
//!   coarse-level smoothing of the field (§6) the switch `field_smoothing`
//!   (`stages/field/coarse_field_smoothing.rs`). "Coarse levels" are the coarser half
//!   ([`coarse_level`]). With integration a coarse level's stencil reach grows to
//!   `2 N_h s_max` (see `widen_for_integration`).
//! - With a feature mask (`analyse_exemplar.feature_mask`) voxels carry their triple's
//!   appearance-space colour for matching ([`SolidAnalysisRef::match_colour`]); what is
//!   output stays the colour.
//! - Working values live in 8³ chunks allocated only where the dependent set is; the
//!   dependency bytes are worked out densely over the bounding box of a batch's dependent set
//!   (one byte per voxel, two more while dilating) and then kept in the same chunks.
//!
//! # Memory
//!
//! A level's missing bricks are synthesized in batches ([`BatchLimits`]): what is resident at
//! once is one batch's dense box while it is planned, or one batch's working values (48 bytes
//! per working voxel) while it is synthesized, plus the chunked plans of all batches (about a
//! byte per working voxel) and the bricks of two levels (12 bytes per brick voxel; a level is
//! released to the store once the next finer level is done). None of it grows with the
//! volume beyond the bricks the request needs; at 1024 voxels the cow's surface fits in
//! about 1 GB (BENCHMARKS.md).
//! - The dependency stencil is the cube of radius `r = ⌊N_h √2 s_max + ½⌋` (`⌊N_h √2 s_max⌋ + 1`
//!   with trilinear sampling), or the exact extent for a constant field (see
//!   [`stencil_reach`]); the paper's `D = ⌈N√2⌉`. For the trivial field it is only the
//!   squares of the weighted exemplar planes ([`Stencil`]), which is all a correction reads.

use super::dependent_set::{
    CHUNK, CHUNK_BITS, CHUNK_VOXELS, ChunkedNeed, NeedGrid, Stencil, chunk_local, dependent_box,
    dependent_set,
};
use super::field_integration::integrated_neighbourhood;
use super::history_window::{HistoryWindow, Schedule, Step};
use crate::analyse_exemplar::candidate_triples::{SolidAnalysisRef, Triple, wrap};
use crate::check::ParamError;
use crate::field::coarse_field_smoothing::smooth_field;
use crate::field::quaternion_field::RotationField;
use crate::parameterize::volume_embedding::Volume;
use crate::random::{counter_hash, counter_unit};
use glam::{IVec3, Mat3, Quat, Vec3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeSet, HashMap};
use std::sync::{Arc, Mutex};
use std::time::Instant;

const STREAM_SLAB: u64 = 0x51AB;
const STREAM_JITTER: u64 = 0x7177;

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

    fn validate(&self) -> Result<(), SolidError> {
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

/// A set of finest-level voxels: a box with a bit per voxel.
#[derive(Clone, Debug, PartialEq)]
pub struct VoxelRequest {
    lo: IVec3,
    dims: IVec3,
    bits: Vec<u64>,
}

impl VoxelRequest {
    /// The voxels of `[lo, hi)` for which `f` holds.
    pub fn from_fn(lo: [i32; 3], hi: [i32; 3], f: impl Fn([i32; 3]) -> bool) -> VoxelRequest {
        let lo = IVec3::from(lo);
        let dims = (IVec3::from(hi) - lo).max(IVec3::ZERO);
        let n = dims.x as usize * dims.y as usize * dims.z as usize;
        let mut bits = vec![0u64; n.div_ceil(64)];
        let mut i = 0;
        for z in 0..dims.z {
            for y in 0..dims.y {
                for x in 0..dims.x {
                    let v = lo + IVec3::new(x, y, z);
                    if f(v.into()) {
                        bits[i / 64] |= 1 << (i % 64);
                    }
                    i += 1;
                }
            }
        }
        VoxelRequest { lo, dims, bits }
    }

    /// Every voxel of `[lo, hi)`.
    pub fn from_box(lo: [i32; 3], hi: [i32; 3]) -> VoxelRequest {
        VoxelRequest::from_fn(lo, hi, |_| true)
    }

    /// These voxels.
    pub fn from_voxels(voxels: &[[i32; 3]]) -> VoxelRequest {
        if voxels.is_empty() {
            return VoxelRequest::from_box([0; 3], [0; 3]);
        }
        let lo = voxels.iter().fold(IVec3::MAX, |a, &v| a.min(v.into()));
        let hi = voxels.iter().fold(IVec3::MIN, |a, &v| a.max(v.into())) + 1;
        let mut r = VoxelRequest::from_fn(lo.into(), hi.into(), |_| false);
        for &v in voxels {
            let i = r.index(v.into());
            r.bits[i / 64] |= 1 << (i % 64);
        }
        r
    }

    /// The finest voxels of `volume` that a plane (through `point`, with normal `normal`, in
    /// object space) passes through: a cross-section.
    pub fn plane(volume: &Volume, point: Vec3, normal: Vec3) -> VoxelRequest {
        let n = normal.normalize_or(Vec3::Z);
        let half = 0.5 * volume.voxel * (n.x.abs() + n.y.abs() + n.z.abs());
        let hi = [
            volume.dims[0] as i32,
            volume.dims[1] as i32,
            volume.dims[2] as i32,
        ];
        VoxelRequest::from_fn([0; 3], hi, |v| {
            let c = volume.centre(IVec3::from(v));
            (c - point).dot(n).abs() <= half
        })
    }

    #[inline]
    fn index(&self, v: IVec3) -> usize {
        let q = v - self.lo;
        ((q.z as usize * self.dims.y as usize) + q.y as usize) * self.dims.x as usize + q.x as usize
    }

    pub fn contains(&self, v: [i32; 3]) -> bool {
        let v = IVec3::from(v);
        let q = v - self.lo;
        if !(q.cmpge(IVec3::ZERO).all() && q.cmplt(self.dims).all()) {
            return false;
        }
        let i = self.index(v);
        self.bits[i / 64] >> (i % 64) & 1 == 1
    }

    /// Number of voxels.
    pub fn len(&self) -> usize {
        self.bits.iter().map(|b| b.count_ones() as usize).sum()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The voxels, z-major then y then x.
    pub fn voxels(&self) -> impl Iterator<Item = [i32; 3]> + '_ {
        let (nx, ny) = (self.dims.x as usize, self.dims.y as usize);
        self.bits.iter().enumerate().flat_map(move |(wi, &word)| {
            let mut w = word;
            std::iter::from_fn(move || {
                if w == 0 {
                    return None;
                }
                let b = w.trailing_zeros() as usize;
                w &= w - 1;
                let i = wi * 64 + b;
                Some(
                    (self.lo
                        + IVec3::new(
                            (i % nx) as i32,
                            ((i / nx) % ny) as i32,
                            (i / (nx * ny)) as i32,
                        ))
                    .into(),
                )
            })
        })
    }
}

/// A brick: the final triples of the `size³` voxels of one dual cell of one level, x fastest.
/// Voxels outside the level's domain hold `Triple::default()`.
#[derive(Clone, Debug, PartialEq)]
pub struct Brick {
    pub level: u32,
    pub coord: [i32; 3],
    pub size: u32,
    pub triples: Vec<Triple>,
}

/// A brick's metadata (with the `triples` array it is the brick's artifact).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct BrickMeta {
    pub level: u32,
    pub coord: [i32; 3],
    pub size: u32,
}

impl Brick {
    pub fn meta(&self) -> BrickMeta {
        BrickMeta {
            level: self.level,
            coord: self.coord,
            size: self.size,
        }
    }

    /// The named arrays to store next to [`Brick::meta`].
    pub fn arrays(&self) -> Vec<(String, &[u8])> {
        vec![("triples".into(), bytemuck::cast_slice(&self.triples))]
    }

    /// Reads a stored brick back, checking its length.
    pub fn from_arrays(meta: BrickMeta, arrays: &[(String, &[u8])]) -> Result<Brick, SolidError> {
        let raw = arrays
            .iter()
            .find(|(n, _)| n == "triples")
            .ok_or_else(|| SolidError::Brick("no array named \"triples\"".into()))?
            .1;
        if raw.len() % std::mem::size_of::<Triple>() != 0 {
            return Err(SolidError::Brick("triples are not whole".into()));
        }
        let triples: Vec<Triple> = raw
            .chunks_exact(std::mem::size_of::<Triple>())
            .map(bytemuck::pod_read_unaligned)
            .collect();
        let want = (meta.size.min(4096) as usize).pow(3);
        if triples.len() != want || meta.size == 0 || meta.size > 4096 {
            return Err(SolidError::Brick(format!(
                "{} triples for a brick of side {}",
                triples.len(),
                meta.size
            )));
        }
        Ok(Brick {
            level: meta.level,
            coord: meta.coord,
            size: meta.size,
            triples,
        })
    }

    #[inline]
    fn at(&self, local: IVec3) -> Triple {
        let s = self.size as usize;
        self.triples[(local.z as usize * s + local.y as usize) * s + local.x as usize]
    }
}

/// Where bricks live; the caller owns it (e.g. the artifact cache, one artifact per brick).
pub trait BrickStore {
    fn get(&self, level: u32, brick: [i32; 3]) -> Option<Arc<Brick>>;
    fn put(&self, level: u32, brick: [i32; 3], b: Arc<Brick>);
    /// The synthesis will not read `level`'s bricks again (its finer level is done): a store
    /// that keeps copies in memory next to a lasting one (the pipeline's cache) drops them
    /// here. A store that is the only home of its bricks keeps them (the default).
    fn release(&self, _level: u32) {}
}

/// Bricks by (level, brick coordinates).
type BrickMap = HashMap<(u32, [i32; 3]), Arc<Brick>>;

/// A brick store in memory.
#[derive(Default, Debug)]
pub struct MemoryBrickStore {
    map: Mutex<BrickMap>,
}

impl MemoryBrickStore {
    pub fn new() -> Self {
        Self::default()
    }
    /// Bricks stored.
    pub fn len(&self) -> usize {
        self.map.lock().expect("store lock").len()
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Keys of the stored bricks of a level, sorted.
    pub fn bricks(&self, level: u32) -> Vec<[i32; 3]> {
        let mut v: Vec<[i32; 3]> = self
            .map
            .lock()
            .expect("store lock")
            .keys()
            .filter(|k| k.0 == level)
            .map(|k| k.1)
            .collect();
        v.sort();
        v
    }
}

impl BrickStore for MemoryBrickStore {
    fn get(&self, level: u32, brick: [i32; 3]) -> Option<Arc<Brick>> {
        self.map
            .lock()
            .expect("store lock")
            .get(&(level, brick))
            .cloned()
    }
    fn put(&self, level: u32, brick: [i32; 3], b: Arc<Brick>) {
        self.map
            .lock()
            .expect("store lock")
            .insert((level, brick), b);
    }
}

/// Work per level; `level` from 1 (coarsest).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct LevelReport {
    pub level: u32,
    /// Bricks the request depends on at this level.
    pub bricks_needed: u64,
    /// Of those, computed by this call.
    pub bricks_computed: u64,
    /// Of those, found in the store.
    pub bricks_reused: u64,
    /// Voxels synthesized (including those only upsampled).
    pub voxels: u64,
    /// Voxel corrections.
    pub corrections: u64,
    /// Candidate comparisons.
    pub comparisons: u64,
    /// Wall time.
    pub seconds: f64,
    /// Batches the missing bricks were synthesized in (see [`BatchLimits`]).
    pub batches: u64,
    /// Working voxels (whole 8³ chunks) of the largest batch: what the level's working
    /// values took room for at once.
    pub largest_batch_voxels: u64,
}

/// What [`SolidSynthesis::synthesize`] did.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SynthesisReport {
    /// Coarsest level first.
    pub levels: Vec<LevelReport>,
}

impl SynthesisReport {
    pub fn bricks_computed(&self) -> u64 {
        self.levels.iter().map(|l| l.bricks_computed).sum()
    }
    pub fn voxels(&self) -> u64 {
        self.levels.iter().map(|l| l.voxels).sum()
    }
}

/// The dependent set of a request at one level (from an empty store).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LevelDependency {
    pub level: u32,
    /// Bricks, sorted.
    pub bricks: Vec<[i32; 3]>,
    /// Voxels in the dependent set (including those only upsampled), each counted once.
    pub voxels: u64,
    /// Voxel corrections the set needs, each voxel's counted once.
    pub corrections: u64,
    /// Voxels synthesized: `voxels` plus the overlap of the level's batches, which is
    /// synthesized once per batch (equal when the level is one batch).
    pub batch_voxels: u64,
    /// Upper bound of the level's impact distance, in its voxels.
    pub impact_distance: i32,
}

/// A voxel's working value: triple and its colour at the level.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct VoxelState {
    t: Triple,
    c: [f32; 3],
}

/// Working values of one batch of a level, slot for slot with the kept chunks of its
/// [`ChunkedNeed`]; `start` is the snapshot at the start of a stage with barriers.
struct States<'n> {
    need: &'n ChunkedNeed,
    cur: Vec<VoxelState>,
    start: Vec<VoxelState>,
}

impl<'n> States<'n> {
    fn new(need: &'n ChunkedNeed) -> States<'n> {
        States {
            need,
            cur: vec![VoxelState::default(); need.chunk_voxels() as usize],
            start: Vec::new(),
        }
    }

    #[inline]
    fn slot(&self, p: IVec3) -> usize {
        self.need.slot_in_set(p)
    }
}

/// Per-thread buffers of a correction.
struct Scratch {
    vec: Vec<f32>,
    proj: [Vec<f32>; 3],
    cands: Vec<Triple>,
    /// The distinct candidates, in the order of first visits.
    unique: Vec<Triple>,
    /// Sample positions of an integrated neighbourhood (`field_integration`).
    positions: Vec<Vec3>,
    /// Open-addressing set of the triples seen in this correction (entries stamped with
    /// `stamp`): 16 bytes an entry, the triple itself is the key.
    seen: Vec<(Triple, u32)>,
    /// Plane distances of this correction (entries stamped with `stamp`).
    memo: PlaneDistances,
    stamp: u32,
}

/// The distance from a voxel's projected neighbourhood in plane `P` to the feature of one
/// exemplar pixel of that plane, remembered per correction. A candidate's distance is the
/// weighted sum of one such distance per plane, and the candidates share them: the k
/// candidates of one pixel of `P` all have that pixel as their `P` coordinate (and mostly the
/// neighbour's shifted triple too), so each (plane, pixel) is compared once and its
/// feature read once. The sums add the same values in the same order: the same bits.
struct PlaneDistances {
    /// Open addressing: (plane, pixel) key, stamp, distance.
    entries: Vec<(u64, u32, f32)>,
}

impl PlaneDistances {
    /// A table for at most `capacity` distances per correction: always a free entry, and
    /// small enough (8 KiB for k = 4) to stay in the first-level cache beside the rest.
    fn new(capacity: usize) -> PlaneDistances {
        PlaneDistances {
            entries: vec![(0, 0, 0.0); (capacity + 1).next_power_of_two()],
        }
    }

    /// The distance of `plane`'s pixel `px` in correction `stamp`, from `compute` the first
    /// time it is asked for.
    #[inline(always)]
    fn get(
        &mut self,
        stamp: u32,
        plane: usize,
        px: [u16; 2],
        compute: impl FnOnce() -> f32,
    ) -> f32 {
        let key = ((plane as u64) << 32) | ((px[1] as u64) << 16) | px[0] as u64;
        let mask = self.entries.len() - 1;
        let mut i = (key.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 40) as usize & mask;
        loop {
            let e = &mut self.entries[i];
            if e.1 != stamp {
                let d = compute();
                *e = (key, stamp, d);
                return d;
            }
            if e.0 == key {
                return e.2;
            }
            i = (i + 1) & mask;
        }
    }

    /// Forgets every stamp (when the stamps wrap around).
    fn clear(&mut self) {
        self.entries.iter_mut().for_each(|e| e.1 = 0);
    }
}

/// The parents' bricks of a level.
struct Parents {
    m: i32,
    bricks: HashMap<[i32; 3], Arc<Brick>>,
}

impl Parents {
    #[inline]
    fn get(&self, v: IVec3) -> Triple {
        let b = brick_of(self.m, v);
        let local = v - brick_origin(self.m, b);
        self.bricks[&<[i32; 3]>::from(b)].at(local)
    }
}

#[inline]
fn brick_of(m: i32, v: IVec3) -> IVec3 {
    (v - IVec3::splat(m / 2)).div_euclid(IVec3::splat(m))
}

#[inline]
fn brick_origin(m: i32, b: IVec3) -> IVec3 {
    b * m + IVec3::splat(m / 2)
}

/// One planned level: its needed and missing bricks, the missing ones in batches.
struct LevelPlan {
    needed: Vec<[i32; 3]>,
    missing: Vec<[i32; 3]>,
    batches: Vec<Batch>,
}

impl LevelPlan {
    fn voxels(&self) -> u64 {
        self.batches.iter().map(|b| b.need.voxels()).sum()
    }

    /// Distinct voxels and corrections of the union of the batches' sets: a voxel in several
    /// batches counts once, at the most versions any batch needs of it (the same versions:
    /// each batch's set is closed under the same dependencies).
    fn distinct(&self) -> (u64, u64) {
        if let [b] = &self.batches[..] {
            return (b.need.voxels(), b.need.corrections());
        }
        // 8³ blocks on the level's own lattice, so every batch's voxel lands in one place.
        let mut union: std::collections::HashMap<IVec3, Box<[u8; CHUNK_VOXELS]>> =
            std::collections::HashMap::new();
        for b in &self.batches {
            for (k, origin) in b.need.origins().iter().enumerate() {
                for (m, &x) in b.need.chunk(k).iter().enumerate() {
                    if x == 0 {
                        continue;
                    }
                    let v = *origin + chunk_local(m);
                    let block = union
                        .entry(v >> 3)
                        .or_insert_with(|| Box::new([0; CHUNK_VOXELS]));
                    let w = v & 7;
                    let slot = &mut block[((w.z * 8 + w.y) * 8 + w.x) as usize];
                    *slot = (*slot).max(x);
                }
            }
        }
        let (mut voxels, mut corrections) = (0, 0);
        for block in union.values() {
            for &x in block.iter() {
                voxels += (x > 0) as u64;
                corrections += x.saturating_sub(1) as u64;
            }
        }
        (voxels, corrections)
    }
}

/// Some of a level's missing bricks, synthesized together from their joint dependent set.
struct Batch {
    bricks: Vec<[i32; 3]>,
    need: ChunkedNeed,
    /// Bricks of the level below holding the parents of `need`'s voxels.
    parents: Vec<[i32; 3]>,
}

/// How much of a level is synthesized at once. A level's missing bricks are split (halving
/// their sorted list, x-major, so each part stays a slab of the volume) until each part's
/// dependent set fits both limits, or is one brick. The halves' dependent sets overlap near
/// the cut and the overlap is synthesized twice, to the same values (a brick is a pure
/// function of its coordinates, see the module docs); the output does not depend on the
/// limits.
///
/// What this bounds: planning a batch allocates its dependent set densely over its box
/// (`box_voxels` bytes, and about eight more per voxel for a moment while dilating);
/// synthesizing it holds two [`VoxelState`]s of 24 bytes per working voxel
/// (`2 · 24 · chunk_voxels`), the corrections of one step (an eighth of them with
/// subpasses), the batch's parent bricks and the bricks it makes. Between batches only the
/// plans (about a byte per working voxel) and the bricks of the level being made and the
/// level below stay resident; a level's bricks are released to the store once the next
/// finer level is done.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BatchLimits {
    /// Voxels of the dense box of a batch's dependent set.
    pub box_voxels: u64,
    /// Working voxels (kept 8³ chunks) of a batch.
    pub chunk_voxels: u64,
}

impl Default for BatchLimits {
    /// 64 Mi voxels of box and 16 Mi working voxels: about 0.6 GB for planning a batch and
    /// 0.8 GB of working values. A 512-voxel cow's surface is one batch per level; at 1024 the
    /// finest level is four.
    fn default() -> Self {
        BatchLimits {
            box_voxels: 1 << 26,
            chunk_voxels: 1 << 24,
        }
    }
}

/// The dependency stencil radius of each level: the largest per-axis offset, in voxels of the
/// level, of any voxel a correction reads (neighbourhood samples, trilinear corners, candidate
/// positions). The dependent set dilates by the cube of this radius, so it must bound every
/// read, and each voxel it overstates thickens every ring of the set by one voxel per side.
///
/// A sample at in-plane offset `(i, j)` sits at `v + s (i c₁ + j c₂)` with `c₁, c₂` two
/// columns of the local frame: per axis at most `e = N_h s (|c₁ₐ| + |c₂ₐ|)` from `v`, which is
/// `N_h s_max √2` in general and exact for a constant field.
/// - Nearest sampling reads `[v + x]` (halves up), so `|offset| ≤ ⌊e + ½⌋`, not `⌈e⌉`: for
///   the trivial field at `N = 9`, `e = 4` and the reach is 4 where `⌈4 + ε⌉` gave 5.
/// - Trilinear sampling reads `⌊v + x⌋` and `⌊v + x⌋ + 1`, the second only with a non-zero
///   weight, so `⌊e⌋ + 1` in general. When the field is the identity at an integral scale
///   everywhere (`RotationField::trivial`), every sample position is an integer (the
///   interpolated frame is exactly the identity and the scale exactly `s` in `f32`), the
///   `+1` corners have weight 0 and are never read, and the reach is `N_h s`.
///
/// A margin `δ` covers `f32` rounding of positions (it grows with the volume's side).
///
/// On the lattice (the trivial field) the reads are also flat: each weighted exemplar plane
/// `p` is sampled at `v + s (i e_p + j e_{p+1})`, its candidates at `v ± e_p ± e_{p+1}`, so
/// the stencil is the union of those planes' squares, not the cube (returned as the planes
/// read; `None` off the lattice).
fn stencil_reach(
    analysis: &SolidAnalysisRef,
    field: &RotationField,
    pyramid: &Pyramid,
    params: &SolidParams,
) -> (Vec<i32>, Option<[bool; 3]>) {
    let q0 = field.rotations[0];
    let s0 = field.scales[0];
    let constant =
        field.rotations.iter().all(|q| *q == q0) && field.scales.iter().all(|s| *s == s0);
    let lattice =
        constant && (q0 == glam::Quat::IDENTITY || q0 == -glam::Quat::IDENTITY) && s0 == s0.round();
    let per_axis = if constant {
        let mat = Mat3::from_quat(q0);
        let mut e = 0.0f32;
        for p in 0..3 {
            let (a, b) = (mat.col(p), mat.col((p + 1) % 3));
            for i in 0..3 {
                e = e.max(a[i].abs() + b[i].abs());
            }
        }
        e * s0
    } else {
        std::f32::consts::SQRT_2 * field.scales.iter().fold(0.0f32, |a, &b| a.max(b))
    };
    let side = pyramid.volume.dims.iter().copied().max().unwrap_or(1) as f32;
    let delta = 1e-3 + side * f32::EPSILON * 8.0;
    let planes = lattice.then(|| analysis.weights().map(|w| w != 0.0));
    let reach = params
        .levels
        .iter()
        .enumerate()
        .map(|(li, l)| {
            let nh = (analysis.n(li) / 2) as f32;
            let r = if lattice {
                (nh * per_axis) as i32
            } else {
                let e = nh * per_axis + delta;
                if l.trilinear {
                    e.floor() as i32 + 1
                } else {
                    (e + 0.5).floor() as i32
                }
            };
            r.max(1)
        })
        .collect();
    (reach, planes)
}

/// With `field_integration`, a level's samples lie along integral lines up to `bound` voxels
/// from the centre per axis (`2 N_h s_max`: `|i| + |j|` steps of at most `s_max` each), not
/// `N_h √2 s_max`: its reach grows to cover them (trilinear sampling reads one more voxel).
fn widen_for_integration(
    reach: &mut [i32],
    integrate: &[Option<f32>],
    params: &SolidParams,
    pyramid: &Pyramid,
) {
    let side = pyramid.volume.dims.iter().copied().max().unwrap_or(1) as f32;
    let delta = 1e-3 + side * f32::EPSILON * 8.0;
    for (li, r) in reach.iter_mut().enumerate() {
        if let Some(bound) = integrate[li] {
            let e = bound + delta;
            let need = if params.levels[li].trilinear {
                e.floor() as i32 + 1
            } else {
                (e + 0.5).floor() as i32
            };
            *r = (*r).max(need);
        }
    }
}

/// A configured synthesis: analysis, field, volume and parameters, validated.
pub struct SolidSynthesis<'a> {
    analysis: SolidAnalysisRef<'a>,
    field: &'a RotationField,
    /// Per level, the field smoothed for it (`field_smoothing`), if it is.
    smoothed: Vec<Option<RotationField>>,
    /// Per level, the per-axis bound of an integrated sample's offset, if the level samples
    /// along the field (`field_integration`).
    integrate: Vec<Option<f32>>,
    pyramid: Pyramid,
    params: SolidParams,
    schedules: Vec<Schedule>,
    reach: Vec<i32>,
    /// The exemplar planes a correction reads, when they are axis planes (the trivial field):
    /// the stencil is then their squares, not the cube.
    planes: Option<[bool; 3]>,
    /// `basis · mean` per (level, image), to project without centring.
    mean_proj: Vec<Vec<Vec<f32>>>,
    /// Per (level, image), the basis in row pairs for [`project_avx512`] (see [`pair_rows`]),
    /// when the CPU has AVX-512F (`None` otherwise; an image's rows are empty where the basis
    /// has fewer than 8 values or 2 rows, and the AVX2 projection runs). The token is the
    /// detection's proof, which the unsafe call in the kernel relies on.
    paired: Option<(Avx512, Vec<Vec<Vec<f32>>>)>,
    limits: BatchLimits,
    /// Per level, the scale of its field where that field is the identity rotation at one
    /// scale everywhere ([`uniform_scale`]): then every look-up returns exactly that.
    uniform: Vec<Option<f32>>,
}

/// `Some(s)` when every rotation of `field` is the identity and every scale is `s`. Then
/// [`RotationField::rotation_at`] is exactly `Quat::IDENTITY` and [`RotationField::scale_at`]
/// exactly `s` everywhere: the look-ups sum the eight corners' values times weights in `f64`
/// (for the rotation: `(0, 0, 0, S)` with `S = Σ w ≈ 1`, which normalizes to within an `f64`
/// rounding of 1; for the scale `s·S`), then round to `f32`, and a value within a few `f64`
/// roundings of an `f32` number rounds to that number. A rotation field of another constant
/// rotation is not taken: its normalization could move a component across an `f32` rounding.
fn uniform_scale(field: &RotationField) -> Option<f32> {
    // Scales are validated finite (0.1..=10, quaternion_field.rs); an infinite one would not
    // be exact (a corner of weight 0 gives inf·0 = NaN in the look-up).
    let s = *field.scales.first()?;
    if !s.is_finite() {
        return None;
    }
    let identity = |q: &Quat| q.x == 0.0 && q.y == 0.0 && q.z == 0.0 && q.w == 1.0;
    (field.rotations.iter().all(identity) && field.scales.iter().all(|x| *x == s)).then_some(s)
}

impl<'a> SolidSynthesis<'a> {
    pub fn new(
        analysis: SolidAnalysisRef<'a>,
        field: &'a RotationField,
        volume: Volume,
        params: SolidParams,
    ) -> Result<Self, SolidError> {
        let pyramid = Pyramid {
            volume,
            levels: params.levels.len() as u32,
        };
        pyramid.validate()?;
        params.validate()?;
        if analysis.levels() != pyramid.levels {
            return Err(SolidError::Levels {
                analysis: analysis.levels(),
                params: pyramid.levels,
            });
        }
        let g = field.grid.len();
        if g == 0 || field.rotations.len() != g || field.scales.len() != g {
            return Err(SolidError::Field(format!(
                "{} rotations and {} scales on a grid of {g} nodes",
                field.rotations.len(),
                field.scales.len()
            )));
        }
        if let Some(i) = field
            .scales
            .iter()
            .position(|s| !(s.is_finite() && *s >= 0.01 && *s <= 100.0))
        {
            return Err(SolidError::Field(format!(
                "scale {} at node {i} is outside 0.01..=100",
                field.scales[i]
            )));
        }
        if let Some(i) = field
            .rotations
            .iter()
            .position(|q| !(q.is_finite() && (q.length() - 1.0).abs() < 1e-3))
        {
            return Err(SolidError::Field(format!(
                "rotation at node {i} is not a unit quaternion"
            )));
        }
        let m = params.cell as i32;
        let schedules: Vec<Schedule> = params
            .levels
            .iter()
            .map(|l| match l.scheme {
                Scheme::Plain => Schedule::plain(l.passes, l.subpasses),
                Scheme::Grid => Schedule::grid(l.passes, l.subpasses, m),
                Scheme::DualGrid => Schedule::dual_grid(l.passes, l.subpasses, m),
            })
            .collect();
        let constant = field.rotations.iter().all(|q| *q == field.rotations[0])
            && field.scales.iter().all(|s| *s == field.scales[0]);
        let nl = pyramid.levels as usize;
        let smoothed: Vec<Option<RotationField>> = (0..nl)
            .map(|li| {
                let on = params.field_smoothing > 0.0 && coarse_level(li, nl) && !constant;
                on.then(|| {
                    let side = pyramid.step(li as u32 + 1) as f32 * volume.voxel;
                    smooth_field(field, params.field_smoothing * side)
                })
            })
            .collect();
        // Along a constant field the integral lines are the frame's straight lines: the
        // centre's frame samples them exactly.
        let s_max = field.scales.iter().fold(0.0f32, |a, &b| a.max(b));
        let integrate: Vec<Option<f32>> = (0..nl)
            .map(|li| {
                let on = params.field_integration && coarse_level(li, nl) && !constant;
                on.then(|| 2.0 * (analysis.n(li) / 2) as f32 * s_max)
            })
            .collect();
        let (mut reach, mut planes) = stencil_reach(&analysis, field, &pyramid, &params);
        if integrate.iter().any(Option::is_some) {
            // Integral lines leave the planes (never on the lattice, which is constant).
            planes = None;
        }
        widen_for_integration(&mut reach, &integrate, &params, &pyramid);
        let images = analysis.meta.images as usize;
        let mean_proj = (0..pyramid.levels as usize)
            .map(|li| {
                (0..images)
                    .map(|img| {
                        let (mean, basis) = analysis.pca(li, img);
                        basis
                            .chunks_exact(mean.len())
                            .map(|row| row.iter().zip(mean).map(|(a, b)| a * b).sum())
                            .collect()
                    })
                    .collect()
            })
            .collect();
        let uniform = (0..nl)
            .map(|li| uniform_scale(smoothed[li].as_ref().unwrap_or(field)))
            .collect();
        let paired = Avx512::detect().map(|token| {
            let rows = (0..pyramid.levels as usize)
                .map(|li| {
                    (0..images)
                        .map(|img| {
                            let (mean, basis) = analysis.pca(li, img);
                            pair_rows(basis, mean.len())
                        })
                        .collect()
                })
                .collect();
            (token, rows)
        });
        Ok(SolidSynthesis {
            analysis,
            field,
            smoothed,
            integrate,
            pyramid,
            params,
            schedules,
            reach,
            planes,
            mean_proj,
            paired,
            limits: BatchLimits::default(),
            uniform,
        })
    }

    /// The field array level `li` reads: smoothed on the coarse levels with
    /// `field_smoothing`, else the field itself.
    pub fn field_of(&self, li: usize) -> &RotationField {
        self.smoothed[li].as_ref().unwrap_or(self.field)
    }

    /// The rotation and scale of array level `li`'s field at object-space `pos`: what
    /// [`RotationField::rotation_at`] and [`RotationField::scale_at`] return, without the
    /// look-up where the field is the identity everywhere at one scale (see [`uniform_scale`]).
    #[inline]
    fn rotation_scale(&self, li: usize, pos: Vec3) -> (Quat, f32) {
        if let Some(s) = self.uniform[li] {
            return (Quat::IDENTITY, s);
        }
        let f = self.field_of(li);
        (f.rotation_at(pos), f.scale_at(pos))
    }

    /// The finest level's grid.
    pub fn volume(&self) -> &Volume {
        &self.pyramid.volume
    }

    /// The pyramid over it (what bricks depend on of the volume).
    pub fn pyramid(&self) -> &Pyramid {
        &self.pyramid
    }

    /// Pyramid levels L.
    pub fn levels(&self) -> u32 {
        self.pyramid.levels
    }

    pub fn analysis(&self) -> &SolidAnalysisRef<'a> {
        &self.analysis
    }

    /// The dependency stencil radius of each level (coarsest first).
    pub fn reach(&self) -> &[i32] {
        &self.reach
    }

    /// The same synthesis with a stencil `extra` voxels wider on every level: the same voxel
    /// results from a larger dependent set (the stencil before it was made exact; for tests
    /// and the benchmark's before/after counts).
    pub fn widen_reach(mut self, extra: i32) -> Self {
        self.reach.iter_mut().for_each(|r| *r += extra.max(0));
        self.planes = None;
        self
    }

    /// The same synthesis dilating by the whole cube of the reach even where the reads lie in
    /// planes: the same voxel results from a larger dependent set (the stencil before it was
    /// made flat; for tests and the benchmark's before/after counts).
    pub fn cube_stencil(mut self) -> Self {
        self.planes = None;
        self
    }

    /// What a correction of array level `li` reads, as the dependent set dilates by it.
    pub fn stencil(&self, li: usize) -> Stencil {
        Stencil {
            reach: self.reach[li],
            planes: self.planes,
        }
    }

    /// The same synthesis in batches of other sizes (the voxels do not change).
    pub fn with_batch_limits(mut self, limits: BatchLimits) -> Self {
        self.limits = limits;
        self
    }

    /// The schedule of each level (coarsest first).
    pub fn schedules(&self) -> &[Schedule] {
        &self.schedules
    }

    fn m(&self) -> i32 {
        self.params.cell as i32
    }

    /// Brick holding voxel `v` (any level).
    pub fn brick_of(&self, v: [i32; 3]) -> [i32; 3] {
        brick_of(self.m(), IVec3::from(v)).into()
    }

    /// The voxels `[lo, hi)` of brick `b` (any level).
    pub fn brick_box(&self, b: [i32; 3]) -> ([i32; 3], [i32; 3]) {
        let lo = brick_origin(self.m(), IVec3::from(b));
        (lo.into(), (lo + self.m()).into())
    }

    /// The finest bricks a request touches (inside the volume), sorted: what a sharded run
    /// splits among its shards.
    pub fn request_bricks(&self, request: &VoxelRequest) -> Vec<[i32; 3]> {
        let dims = self.pyramid.level_dims(self.pyramid.levels);
        let mut set = BTreeSet::new();
        for v in request.voxels() {
            let v = IVec3::from(v);
            if v.cmpge(IVec3::ZERO).all() && v.cmplt(dims).all() {
                set.insert(<[i32; 3]>::from(brick_of(self.m(), v)));
            }
        }
        set.into_iter().collect()
    }

    /// Bricks of the level below holding the parents of the voxels of `need`.
    fn parent_bricks(&self, need: &NeedGrid) -> Vec<[i32; 3]> {
        if need.need.is_empty() {
            return vec![];
        }
        let m = self.m();
        let blo = brick_of(m, need.lo.div_euclid(IVec3::splat(2)));
        let bhi = brick_of(m, (need.lo + need.n - 1).div_euclid(IVec3::splat(2)));
        let bn = bhi - blo + 1;
        let mut mark = vec![false; (bn.x * bn.y * bn.z) as usize];
        // Row by row, skipping empty rows, with each x's brick column worked out once: a
        // batch's box is tens of millions of voxels, most of them not needed.
        let nx = need.n.x as usize;
        let brick_x: Vec<usize> = (0..need.n.x)
            .map(|x| {
                let v = IVec3::new(need.lo.x + x, need.lo.y, need.lo.z);
                (brick_of(m, v.div_euclid(IVec3::splat(2))).x - blo.x) as usize
            })
            .collect();
        for (row, xs) in need.need.chunks(nx).enumerate() {
            if xs.iter().fold(0u8, |a, &b| a | b) == 0 {
                continue;
            }
            let b = brick_of(m, need.position(row * nx).div_euclid(IVec3::splat(2))) - blo;
            let base = ((b.z * bn.y + b.y) * bn.x) as usize;
            for (x, &v) in xs.iter().enumerate() {
                if v > 0 {
                    mark[base + brick_x[x]] = true;
                }
            }
        }
        let mut out = vec![];
        for z in 0..bn.z {
            for y in 0..bn.y {
                for x in 0..bn.x {
                    if mark[((z * bn.y + y) * bn.x + x) as usize] {
                        out.push((blo + IVec3::new(x, y, z)).into());
                    }
                }
            }
        }
        out.sort_unstable();
        out
    }

    /// Plans a request level by level from the finest: bricks needed, those missing from
    /// `store` (all of them without a store), and the missing ones in batches with their
    /// dependent sets.
    fn plan(&self, request: &VoxelRequest, store: Option<&dyn BrickStore>) -> Vec<LevelPlan> {
        let levels = self.pyramid.levels;
        let mut plans: Vec<LevelPlan> = Vec::with_capacity(levels as usize);
        let mut needed = self.request_bricks(request);
        for level in (1..=levels).rev() {
            let missing: Vec<[i32; 3]> = needed
                .iter()
                .filter(|b| store.is_none_or(|s| s.get(level, **b).is_none()))
                .copied()
                .collect();
            let batches = self.batches(level, &missing);
            let mut below: Vec<[i32; 3]> = batches
                .iter()
                .flat_map(|b| b.parents.iter().copied())
                .collect();
            below.sort_unstable();
            below.dedup();
            plans.push(LevelPlan {
                needed,
                missing,
                batches,
            });
            needed = below;
        }
        plans.reverse();
        plans
    }

    /// `bricks` (sorted) of `level` in batches within the [`BatchLimits`], each with its
    /// dependent set and parent bricks.
    fn batches(&self, level: u32, bricks: &[[i32; 3]]) -> Vec<Batch> {
        let li = (level - 1) as usize;
        let m = self.m();
        let targets: Vec<(IVec3, IVec3)> = bricks
            .iter()
            .map(|b| {
                let lo = brick_origin(m, IVec3::from(*b));
                (lo, lo + m)
            })
            .collect();
        let (schedule, domain) = (&self.schedules[li], self.pyramid.level_dims(level));
        let Some((lo, hi)) = dependent_box(schedule, domain, &targets, self.reach[li]) else {
            return Vec::new();
        };
        let split = |bricks: &[[i32; 3]]| {
            let (a, b) = bricks.split_at(bricks.len() / 2);
            let mut out = self.batches(level, a);
            out.extend(self.batches(level, b));
            out
        };
        let n = (hi - lo).as_i64vec3();
        if bricks.len() > 1 && (n.x * n.y * n.z) as u64 > self.limits.box_voxels {
            return split(bricks);
        }
        let dense = dependent_set(schedule, domain, &targets, self.stencil(li));
        let need = ChunkedNeed::from_grid(&dense);
        if bricks.len() > 1 && need.chunk_voxels() > self.limits.chunk_voxels {
            return split(bricks);
        }
        let parents = if level > 1 {
            self.parent_bricks(&dense)
        } else {
            Vec::new()
        };
        vec![Batch {
            bricks: bricks.to_vec(),
            need,
            parents,
        }]
    }

    /// The dependent set of a request at brick granularity, per level (coarsest first),
    /// computed backwards from the request as if the store were empty.
    pub fn bricks_needed(&self, request: &VoxelRequest) -> Vec<Vec<[i32; 3]>> {
        self.plan(request, None)
            .into_iter()
            .map(|p| p.needed)
            .collect()
    }

    /// The dependent set of a request per level (coarsest first), from an empty store: bricks,
    /// voxels synthesized and corrections (what Tables 1–2 of the paper count).
    pub fn dependent_set(&self, request: &VoxelRequest) -> Vec<LevelDependency> {
        self.plan(request, None)
            .into_iter()
            .enumerate()
            .map(|(li, p)| {
                let (voxels, corrections) = p.distinct();
                LevelDependency {
                    level: li as u32 + 1,
                    voxels,
                    corrections,
                    batch_voxels: p.voxels(),
                    bricks: p.needed,
                    impact_distance: self.schedules[li].impact_distance(self.reach[li]),
                }
            })
            .collect()
    }

    /// What [`SolidSynthesis::synthesize`] would do with `store`, per level (coarsest first),
    /// without doing it: the bricks needed, to compute and found (voxel counts left 0).
    pub fn plan_report(&self, request: &VoxelRequest, store: &dyn BrickStore) -> Vec<LevelReport> {
        self.plan(request, Some(store))
            .into_iter()
            .enumerate()
            .map(|(li, p)| LevelReport {
                level: li as u32 + 1,
                bricks_needed: p.needed.len() as u64,
                bricks_computed: p.missing.len() as u64,
                bricks_reused: (p.needed.len() - p.missing.len()) as u64,
                ..Default::default()
            })
            .collect()
    }

    /// Synthesizes every brick the request depends on that `store` lacks, coarsest level
    /// first, and puts them in `store`.
    pub fn synthesize(
        &self,
        request: &VoxelRequest,
        store: &dyn BrickStore,
    ) -> Result<SynthesisReport, SolidError> {
        let plans = self.plan(request, Some(store));
        let mut report = SynthesisReport::default();
        for (li, plan) in plans.iter().enumerate() {
            let level = li as u32 + 1;
            let t0 = Instant::now();
            let mut lr = LevelReport {
                level,
                bricks_needed: plan.needed.len() as u64,
                bricks_computed: plan.missing.len() as u64,
                bricks_reused: (plan.needed.len() - plan.missing.len()) as u64,
                ..Default::default()
            };
            for batch in &plan.batches {
                let mut parents = Parents {
                    m: self.m(),
                    bricks: HashMap::new(),
                };
                for &b in &batch.parents {
                    let brick = store.get(level - 1, b).ok_or(SolidError::MissingBrick {
                        level: level - 1,
                        brick: b,
                    })?;
                    parents.bricks.insert(b, brick);
                }
                let (bricks, comparisons) =
                    self.run_level(li, &batch.need, &parents, &batch.bricks);
                drop(parents);
                for (b, brick) in batch.bricks.iter().zip(bricks) {
                    store.put(level, *b, Arc::new(brick));
                }
                lr.voxels += batch.need.voxels();
                lr.corrections += batch.need.corrections();
                lr.comparisons += comparisons;
                lr.batches += 1;
                lr.largest_batch_voxels = lr.largest_batch_voxels.max(batch.need.chunk_voxels());
            }
            // Nothing reads the level below again: its finer level is complete.
            if level > 1 {
                store.release(level - 1);
            }
            lr.seconds = t0.elapsed().as_secs_f64();
            report.levels.push(lr);
        }
        Ok(report)
    }

    /// Synthesizes every brick `voxels` (finest level) depend on that `store` lacks, then
    /// returns their triples, in order, with the work done per level (also logged).
    pub fn synthesize_voxels(
        &self,
        voxels: &[[i32; 3]],
        store: &dyn BrickStore,
    ) -> Result<(Vec<Triple>, SynthesisReport), SolidError> {
        let report = self.synthesize(&VoxelRequest::from_voxels(voxels), store)?;
        for l in &report.levels {
            tracing::info!(
                "synthesize: level {}: {} bricks needed, {} computed, {} reused; {} voxels, {} corrections",
                l.level,
                l.bricks_needed,
                l.bricks_computed,
                l.bricks_reused,
                l.voxels,
                l.corrections
            );
        }
        let finest = self.pyramid.levels;
        let triples = voxels
            .iter()
            .map(|v| {
                self.triple_at(store, finest, *v)
                    .ok_or(SolidError::NotSynthesized { voxel: *v })
            })
            .collect::<Result<_, _>>()?;
        Ok((triples, report))
    }

    /// The triple of voxel `v` of `level` (1..=L), if its brick is in the store.
    pub fn triple_at(&self, store: &dyn BrickStore, level: u32, v: [i32; 3]) -> Option<Triple> {
        let v = IVec3::from(v);
        if level == 0 || level > self.pyramid.levels {
            return None;
        }
        let dims = self.pyramid.level_dims(level);
        if !(v.cmpge(IVec3::ZERO).all() && v.cmplt(dims).all()) {
            return None;
        }
        let b = brick_of(self.m(), v);
        let brick = store.get(level, b.into())?;
        Some(brick.at(v - brick_origin(self.m(), b)))
    }

    /// The colour of a triple at `level` (the plane-weighted mean of its three texels).
    pub fn colour(&self, level: u32, t: &Triple) -> [f32; 3] {
        self.analysis.colour((level - 1) as usize, t)
    }

    /// The finest-level colour of voxel `v`, if its brick is in the store.
    pub fn colour_at(&self, store: &dyn BrickStore, v: [i32; 3]) -> Option<[f32; 3]> {
        let l = self.pyramid.levels;
        self.triple_at(store, l, v).map(|t| self.colour(l, &t))
    }

    fn wh(&self) -> (u32, u32) {
        (self.analysis.width(), self.analysis.height())
    }

    /// §4.1: the slab tiling of subpart `part` at local coordinate `u` (coarsest level).
    fn slab_triple(&self, part: IVec3, u: IVec3) -> Triple {
        let (w, h) = self.wh();
        let d = self.analysis.meta.params.slab_thickness as i32;
        let sp = self.analysis.spacing(0);
        let layer = u.z.div_euclid(d);
        let dz = u.z - layer * d - d / 2;
        let r = counter_hash(self.params.seed, STREAM_SLAB, voxel_key(0, part));
        let (ox, oy) = ((r % w as u64) as i32, ((r >> 32) % h as u64) as i32);
        let px = [wrap(ox + sp * u.x, w), wrap(oy + sp * u.y, h)];
        self.analysis.slab(px).offset([0, 0, sp * dz], w, h)
    }

    /// §4.1: the initial triple of coarsest voxel `v`.
    fn init(&self, v: IVec3) -> Triple {
        let k = self.params.subpart as i32;
        let part = v.div_euclid(IVec3::splat(k));
        let centre = (part * k).as_vec3() + 0.5 * k as f32;
        let pos = self.pyramid.position(1, v);
        let (q, s) = self.rotation_scale(0, pos);
        let u = centre + q.inverse() * (v.as_vec3() - centre) / s;
        self.slab_triple(part, round_v(u))
    }

    /// §4.2, eq. (3): the upsampled triple of voxel `v` of array level `li ≥ 1`.
    fn upsample(&self, li: usize, v: IVec3, parents: &Parents) -> Triple {
        let level = li as u32 + 1;
        let vp = v.div_euclid(IVec3::splat(2));
        let tp = parents.get(vp);
        let pos = self.pyramid.position(level - 1, vp);
        let (q, s) = self.rotation_scale(li - 1, pos);
        let h = self.analysis.spacing(li) as f32;
        let mut d = q.inverse() * ((v - vp * 2).as_vec3() * (h / s));
        let jitter = self.params.levels[li].jitter;
        if jitter > 0.0 {
            let key = voxel_key(level, v);
            for a in 0..3 {
                let u = counter_unit(self.params.seed, STREAM_JITTER + a as u64, key);
                d[a] += jitter * h * (u - 0.5);
            }
        }
        let (w, hh) = self.wh();
        tp.offset(round_v(d).into(), w, hh)
    }

    /// Runs one batch of a level over its dependent set `need`; returns the bricks `out`
    /// (in order) and the number of candidate comparisons. Work goes chunk by chunk of `need`
    /// (no per-voxel lists): each step maps the chunks in parallel to their corrected voxels,
    /// then commits them (disjoint slots, so in any order).
    fn run_level(
        &self,
        li: usize,
        need: &ChunkedNeed,
        parents: &Parents,
        out: &[[i32; 3]],
    ) -> (Vec<Brick>, u64) {
        let level = li as u32 + 1;
        let mut st = States::new(need);
        st.cur
            .par_chunks_mut(CHUNK_VOXELS)
            .zip(need.origins().par_iter())
            .enumerate()
            .for_each(|(k, (dst, &origin))| {
                for (m, (slot, &x)) in dst.iter_mut().zip(need.chunk(k)).enumerate() {
                    if x == 0 {
                        continue;
                    }
                    let v = origin + chunk_local(m);
                    let t = if li == 0 {
                        self.init(v)
                    } else {
                        self.upsample(li, v, parents)
                    };
                    *slot = VoxelState {
                        t,
                        c: self.analysis.match_colour(li, &t),
                    };
                }
            });
        let schedule = &self.schedules[li];
        let mut comparisons = 0u64;
        let mut stage = usize::MAX;
        for step in schedule.steps() {
            let window = &schedule.stages[step.stage].window;
            if step.stage != stage {
                stage = step.stage;
                if !window.barriers.is_empty() {
                    st.start.clone_from(&st.cur);
                }
            }
            let threshold = 1 + step.version_after() as u8;
            let results: Vec<(Vec<(u16, VoxelState)>, u64)> = need
                .origins()
                .par_iter()
                .enumerate()
                .map_init(
                    || self.scratch(li),
                    |sc, (k, &origin)| {
                        let mut done = Vec::new();
                        let c = self.correct_chunk(
                            li,
                            &st,
                            window,
                            &step,
                            (threshold, origin, need.chunk(k)),
                            sc,
                            &mut done,
                        );
                        (done, c)
                    },
                )
                .collect();
            for (k, (done, c)) in results.into_iter().enumerate() {
                for (m, s) in done {
                    st.cur[k * CHUNK_VOXELS + m as usize] = s;
                }
                comparisons += c;
            }
        }
        st.start = Vec::new();
        let m = self.m();
        let dims = self.pyramid.level_dims(level);
        let bricks = out
            .par_iter()
            .map(|b| {
                let lo = brick_origin(m, IVec3::from(*b));
                let mut triples = Vec::with_capacity((m * m * m) as usize);
                for z in 0..m {
                    for y in 0..m {
                        for x in 0..m {
                            let v = lo + IVec3::new(x, y, z);
                            triples.push(if v.cmpge(IVec3::ZERO).all() && v.cmplt(dims).all() {
                                st.cur[st.slot(v)].t
                            } else {
                                Triple::default()
                            });
                        }
                    }
                }
                Brick {
                    level,
                    coord: *b,
                    size: m as u32,
                    triples,
                }
            })
            .collect();
        (bricks, comparisons)
    }

    fn scratch(&self, li: usize) -> Scratch {
        let c = self.analysis.components(li);
        Scratch {
            vec: vec![0.0; self.analysis.dim(li)],
            proj: [vec![0.0; c], vec![0.0; c], vec![0.0; c]],
            cands: Vec::with_capacity(27 * (self.analysis.k() + 1)),
            unique: Vec::with_capacity(27 * (self.analysis.k() + 1)),
            positions: Vec::new(),
            seen: vec![(Triple::default(), 0); (54 * (self.analysis.k() + 1)).next_power_of_two()],
            // At most one distance per plane of each of the 27 (k + 1) candidates.
            memo: PlaneDistances::new(3 * 27 * (self.analysis.k() + 1)),
            stamp: 0,
        }
    }

    /// The corrections of one chunk in one step: every voxel of the chunk whose needed
    /// version reaches `threshold` and that is active in `step`, pushed to `done` (slot in the
    /// chunk, new value) in slot order; returns the comparisons made. On x86-64 CPUs with
    /// AVX2 the same code runs compiled for AVX2: wider vectors for the same operations in the
    /// same order (Rust never fuses a multiply and an add), so the values are the same bits;
    /// where the CPU also has AVX-512F, its projection is [`project_avx512`] (two basis rows
    /// per register, the same products and sums per lane). Checks: CI's emulated Nehalem runs
    /// the portable path against the locks, this machine's runs the widest path its CPU has,
    /// and each vector projection has a bitwise unit test against the portable one (skipped,
    /// and saying so, on a CPU without it).
    #[allow(clippy::too_many_arguments)]
    fn correct_chunk(
        &self,
        li: usize,
        st: &States,
        window: &HistoryWindow,
        step: &Step,
        chunk: (u8, IVec3, &[u8]),
        sc: &mut Scratch,
        done: &mut Vec<(u16, VoxelState)>,
    ) -> u64 {
        #[cfg(target_arch = "x86_64")]
        if let Some(avx2) = Avx2::detect() {
            // SAFETY: the token exists, so the CPU supports AVX2.
            return unsafe { self.correct_chunk_avx2(avx2, li, st, window, step, chunk, sc, done) };
        }
        self.correct_chunk_portable(Portable, li, st, window, step, chunk, sc, done)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[allow(clippy::too_many_arguments)]
    unsafe fn correct_chunk_avx2(
        &self,
        avx2: Avx2,
        li: usize,
        st: &States,
        window: &HistoryWindow,
        step: &Step,
        chunk: (u8, IVec3, &[u8]),
        sc: &mut Scratch,
        done: &mut Vec<(u16, VoxelState)>,
    ) -> u64 {
        self.correct_chunk_portable(avx2, li, st, window, step, chunk, sc, done)
    }

    /// [`SolidSynthesis::correct_chunk`], compiled for whatever the caller is compiled for;
    /// `kernels` says which projection it may call (a token of [`Avx2`]: the caller has
    /// AVX2, so the projection may use its 8-wide registers).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn correct_chunk_portable<K: Kernels>(
        &self,
        kernels: K,
        li: usize,
        st: &States,
        window: &HistoryWindow,
        step: &Step,
        (threshold, origin, bytes): (u8, IVec3, &[u8]),
        sc: &mut Scratch,
        done: &mut Vec<(u16, VoxelState)>,
    ) -> u64 {
        let mut c = 0u64;
        for (m, &x) in bytes.iter().enumerate() {
            let v = origin + chunk_local(m);
            if x >= threshold && step.active(v) {
                let (s, n) = self.correct(kernels, li, st, window, v, sc);
                done.push((m as u16, s));
                c += n as u64;
            }
        }
        c
    }

    /// The scaled frame (columns `s·q` axes, in voxels of the level) of array level `li` at
    /// `x`, in voxel coordinates of the level.
    fn frame_at(&self, li: usize, x: Vec3) -> Mat3 {
        let pos = self.pyramid.position_f(li as u32 + 1, x);
        let (q, s) = self.rotation_scale(li, pos);
        Mat3::from_quat(q) * s
    }

    /// §4.3: the corrected value of voxel `v` of array level `li`, and the comparisons made.
    #[inline(always)]
    fn correct<K: Kernels>(
        &self,
        kernels: K,
        li: usize,
        st: &States,
        window: &HistoryWindow,
        v: IVec3,
        sc: &mut Scratch,
    ) -> (VoxelState, u32) {
        let a = &self.analysis;
        let level = li as u32 + 1;
        let (w, hh) = self.wh();
        let weights = a.weights();
        let dmax = self.pyramid.level_dims(level) - 1;
        let pos = self.pyramid.position(level, v);
        let (q, s) = self.rotation_scale(li, pos);
        let mat = Mat3::from_quat(q);
        let h = a.spacing(li) as f32;
        let (clo, chi) = window.latest_box(v);
        let read = |p: IVec3| -> &VoxelState {
            let p = p.clamp(IVec3::ZERO, dmax);
            let slot = st.slot(p);
            if p.cmpge(clo).all() && p.cmplt(chi).all() {
                &st.cur[slot]
            } else {
                &st.start[slot]
            }
        };
        let trilinear = self.params.levels[li].trilinear;
        let sample = |p: Vec3| -> [f32; 3] {
            if !trilinear {
                return read(round_v(p)).c;
            }
            let f = p.floor();
            let t = p - f;
            let b = f.as_ivec3();
            let mut acc = [0.0f32; 3];
            for corner in 0..8 {
                let o = IVec3::new(corner & 1, (corner >> 1) & 1, (corner >> 2) & 1);
                let wt = (if o.x == 1 { t.x } else { 1.0 - t.x })
                    * (if o.y == 1 { t.y } else { 1.0 - t.y })
                    * (if o.z == 1 { t.z } else { 1.0 - t.z });
                if wt == 0.0 {
                    continue;
                }
                let c = read(b + o).c;
                for ch in 0..3 {
                    acc[ch] += wt * c[ch];
                }
            }
            acc
        };
        let nh = (a.n(li) / 2) as i32;
        let vf = v.as_vec3();
        let whole = WholeFrame::of(&mat, s, h / s);
        let comps = a.components(li);
        let dim = a.dim(li);
        sc.cands.clear();
        for p in 0..3 {
            if weights[p] == 0.0 {
                continue;
            }
            let c1 = mat.col(p) * s;
            let c2 = mat.col((p + 1) % 3) * s;
            // Gather, row-major: j along image y (c2), i along image x (c1).
            if let Some(bound) = self.integrate[li] {
                // Coarse levels with `field_integration`: along the field's integral lines.
                let frame = |x: Vec3| self.frame_at(li, x);
                integrated_neighbourhood(frame, vf, p, nh, bound, &mut sc.positions);
                for (o, x) in sc.positions.iter().enumerate() {
                    sc.vec[3 * o..3 * o + 3].copy_from_slice(&sample(*x));
                }
            } else {
                let out = &mut sc.vec[..dim];
                match lattice_steps(c1, c2).filter(|_| !trilinear) {
                    // The frame's columns are whole voxel steps along two axes (the trivial
                    // field): every sample position is an integer, exactly, so the nearest voxel
                    // of `v + i c₁ + j c₂` is `v + i a + j b` without rounding, and its clamped
                    // coordinates, slot parts and place in the window (all per axis) are worked
                    // out once per column `i` and row `j`. The same reads as `read`.
                    Some(((ax, sa), (bx, sb))) => {
                        let cx = 3 - ax - bx;
                        let side = (2 * nh + 1) as usize;
                        let latest = (clo, chi);
                        let mut cols = [(0, 0, false); MAX_SIDE];
                        let mut rows = [(0, 0, false); MAX_SIDE];
                        let (cols, rows) = (&mut cols[..side], &mut rows[..side]);
                        axis_parts(st.need, ax, v[ax] - sa * nh, sa, dmax, latest, cols);
                        axis_parts(st.need, bx, v[bx] - sb * nh, sb, dmax, latest, rows);
                        let mut centre = [(0, 0, false)];
                        axis_parts(st.need, cx, v[cx], 0, dmax, latest, &mut centre);
                        gather_lattice(st, rows, cols, centre[0], out);
                    }
                    None => {
                        let mut o = 0;
                        for j in -nh..=nh {
                            let row = vf + c2 * j as f32;
                            for i in -nh..=nh {
                                let col = sample(row + c1 * i as f32);
                                out[o..o + 3].copy_from_slice(&col);
                                o += 3;
                            }
                        }
                    }
                }
            }
            let img = a.image_of(p);
            let (_, basis) = a.pca(li, img);
            let mp = &self.mean_proj[li][img];
            let (x, proj) = (&sc.vec[..dim], &mut sc.proj[p][..comps]);
            #[cfg(target_arch = "x86_64")]
            if K::AVX2 {
                match &self.paired {
                    Some((_avx512, rows)) if !rows[li][img].is_empty() => {
                        // SAFETY: the `Avx512` token exists only after `Avx512::detect`
                        // found AVX-512F and AVX2.
                        unsafe { project_avx512(basis, &rows[li][img], x, mp, proj) };
                    }
                    _ => {
                        // SAFETY: only `Avx2` has `AVX2` set, and a value of it (`kernels`)
                        // exists only after `Avx2::detect` found AVX2.
                        let _proof = kernels;
                        unsafe { project_avx2(basis, x, mp, proj) };
                    }
                }
            } else {
                project(basis, x, mp, proj);
            }
            #[cfg(not(target_arch = "x86_64"))]
            {
                let _ = kernels;
                project(basis, x, mp, proj);
            }
            // Candidates S_P(v), reduced form. Where the neighbours are coherent most of
            // the nine shifted pixels are the same pixel, whose k candidates are then all
            // already listed: a repeated pixel adds none (none could be a first visit in the
            // deduplication below), so its list is skipped before any copying or hashing.
            let mut pixels = [[0u16; 2]; 9];
            let mut distinct = 0;
            for d2 in -1..=1 {
                for d1 in -1..=1 {
                    let triple = |wv: IVec3| read(wv).t;
                    // The neighbour `w`'s triple, the pixel it names in `p` shifted back by
                    // `w`'s exemplar offset `e`, and `−e` rounded (eq. 4).
                    let (tw, px, back) = if let Some(f) = &whole {
                        let wv = f.neighbour(v, p, d1, d2).clamp(IVec3::ZERO, dmax);
                        let tw = triple(wv);
                        let e = f.shift(wv - v);
                        let px = [
                            wrap(tw.c[p][0] as i32 - e[p], w),
                            wrap(tw.c[p][1] as i32 - e[(p + 1) % 3], hh),
                        ];
                        (tw, px, -e)
                    } else {
                        let wv =
                            round_v(vf + c1 * d1 as f32 + c2 * d2 as f32).clamp(IVec3::ZERO, dmax);
                        let tw = triple(wv);
                        let e = mat.transpose() * ((wv - v).as_vec3() * (h / s));
                        let (e1, e2) = (e[p], e[(p + 1) % 3]);
                        let px = [
                            wrap(round_i(tw.c[p][0] as f32 - e1), w),
                            wrap(round_i(tw.c[p][1] as f32 - e2), hh),
                        ];
                        (tw, px, -round_v(e))
                    };
                    if !pixels[..distinct].contains(&px) {
                        pixels[distinct] = px;
                        distinct += 1;
                        // One push each: a copy of a few triples is cheaper inline than
                        // through a memcpy call.
                        for t in a.candidates(li, p, px) {
                            sc.cands.push(*t);
                        }
                    }
                    if self.params.coherent_candidates {
                        // The neighbour's whole triple, shifted back (eq. 4).
                        sc.cands.push(tw.offset(back.into(), w, hh));
                    }
                }
            }
        }
        // Coordinates in planes of weight 0 are never read: canonical zeros, so candidates
        // differing only there are compared once.
        for p in 0..3 {
            if weights[p] == 0.0 {
                sc.cands.iter_mut().for_each(|c| c.c[p] = [0, 0]);
            }
        }
        // Deduplicate (a small hash set of the triples themselves), keeping the order of
        // first visits.
        sc.unique.clear();
        sc.stamp = sc.stamp.wrapping_add(1);
        if sc.stamp == 0 {
            sc.seen.iter_mut().for_each(|e| e.1 = 0);
            sc.memo.clear();
            sc.stamp = 1;
        }
        let mask = sc.seen.len() - 1;
        for c in &sc.cands {
            let mut i = triple_hash(c) & mask;
            loop {
                let e = &mut sc.seen[i];
                if e.1 != sc.stamp {
                    *e = (*c, sc.stamp);
                    sc.unique.push(*c);
                    break;
                }
                if e.0 == *c {
                    break;
                }
                i = (i + 1) & mask;
            }
        }
        let mut best = (f32::INFINITY, sc.unique[0]);
        let prefetch = |t: &Triple| prefetch_candidate(a, li, weights, t);
        // The features of the candidates are scattered over the exemplar's stack: ask for
        // them a few candidates ahead (a hint only; the values compared are the same).
        for t in sc.unique.iter().take(PREFETCH_AHEAD) {
            prefetch(t);
        }
        for (ki, cand) in sc.unique.iter().enumerate() {
            if let Some(next) = sc.unique.get(ki + PREFETCH_AHEAD) {
                prefetch(next);
            }
            let mut e = 0.0f32;
            for p in 0..3 {
                if weights[p] == 0.0 {
                    continue;
                }
                let proj = &sc.proj[p];
                let d = sc.memo.get(sc.stamp, p, cand.c[p], || {
                    squared_distance(proj, a.feature(li, a.image_of(p), cand.c[p]))
                });
                e += weights[p] * d;
                if e >= best.0 {
                    break;
                }
            }
            if e < best.0 {
                best = (e, *cand);
            }
        }
        let comparisons = sc.unique.len() as u32;
        let t = best.1;
        (
            VoxelState {
                t,
                c: a.match_colour(li, &t),
            },
            comparisons,
        )
    }
}

/// The colours of a lattice neighbourhood (see `lattice_steps`) into `out`, row-major: the
/// voxel of row part `rows[j]`, column part `cols[i]` and `centre` (each `(table part, local
/// part, inside the latest window)` of one axis) at `out[3(j·side + i)..]`, from `cur` inside
/// the window and from `start` outside, as `read` does. Its own function, not inlined: inside
/// the big correction loop the output cursor lived on the stack, and every cell waited on
/// its store and reload; here the cursor, the tables and both sources stay in registers.
#[inline(never)]
fn gather_lattice(
    st: &States,
    rows: &[(usize, usize, bool)],
    cols: &[(usize, usize, bool)],
    (tc, lc, inc): (usize, usize, bool),
    out: &mut [f32],
) {
    let (cur, start) = (&st.cur[..], &st.start[..]);
    let mut o = 0;
    for &(tb, lb, inb) in rows {
        let (t, l, inside) = (tb + tc, lb + lc, inb && inc);
        for &(ta, la, ina) in cols {
            let slot = st.need.slot_of_parts(ta + t, la + l);
            let src = if ina && inside { cur } else { start };
            out[o..o + 3].copy_from_slice(&src[slot].c);
            o += 3;
        }
    }
}

/// The parts (see [`ChunkedNeed::axis_part`]) of the positions `start + step·t` along `axis`
/// for `t = 0, 1, …` into `out`, each clamped to `[0, dmax]` first, with whether it lies in the
/// latest window `[lo, hi)` on that axis: the lattice gather's per-column and per-row work.
/// Inlined (a closure here was called out of line, 19 times a plane), with the axis's
/// multipliers worked out once.
#[inline(always)]
fn axis_parts(
    need: &ChunkedNeed,
    axis: usize,
    start: i32,
    step: i32,
    dmax: IVec3,
    (lo, hi): (IVec3, IVec3),
    out: &mut [(usize, usize, bool)],
) {
    let (dmax, lo, hi) = (dmax[axis], lo[axis], hi[axis]);
    let (origin, table, local) = need.axis_multipliers(axis);
    let mut x = start;
    for o in out.iter_mut() {
        let c = x.clamp(0, dmax);
        debug_assert!(c >= origin, "a gather coordinate below the need's origin");
        let q = (c - origin) as usize;
        *o = (
            (q >> CHUNK_BITS) * table,
            (q & (CHUNK as usize - 1)) * local,
            c >= lo && c < hi,
        );
        x += step;
    }
}

/// `⌊x + ½⌋`: nearest integer, halves up (no libm call).
#[inline]
fn round_i(x: f32) -> i32 {
    let t = x + 0.5;
    let i = t as i32;
    if (i as f32) > t { i - 1 } else { i }
}

#[inline]
fn round_v(v: Vec3) -> IVec3 {
    IVec3::new(round_i(v.x), round_i(v.y), round_i(v.z))
}

/// A hash of a triple's 12 bytes (for the deduplication's table; its bits only choose where
/// probing starts, never what is kept).
#[inline(always)]
fn triple_hash(t: &Triple) -> usize {
    let w: [u32; 3] = bytemuck::cast(*t);
    let lo = w[0] as u64 | (w[1] as u64) << 32;
    ((lo ^ (w[2] as u64).rotate_left(29)).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 40) as usize
}

/// A frame whose rotation has entries 0 and ±1 only (the trivial field's signed
/// permutations; the argument below needs no more than that), at a whole scale `s`,
/// with a whole number `h/s` of exemplar pixels per voxel step: the trivial field's. Then
/// the candidates' float arithmetic is exact integer arithmetic, done here in integers: the
/// neighbour `[v + s q d]` is `v + s q d` (every coordinate a small integer, exact in `f32`,
/// so the rounding returns it), and its exemplar offset `qᵀ (w − v) h/s` is a sum of
/// products of 0 or ±1 with small whole numbers, each exact, so its roundings return it
/// too. The same values as the float path, bit for bit.
struct WholeFrame {
    /// The rotation's columns.
    axes: [IVec3; 3],
    s: i32,
    /// Exemplar pixels per voxel step, `h/s`.
    hs: i32,
}

impl WholeFrame {
    /// The whole frame of rotation `mat`, scale `s` and step `hs = h/s` (as the float path
    /// computes it), if it is one; magnitudes are bounded so that every intermediate value
    /// of the float path stays an integer below 2²³ (≤ 3 · 2048 · 1024 ≈ 6.3 M), where
    /// `x + 0.5` and its floor are exact too.
    #[inline]
    fn of(mat: &Mat3, s: f32, hs: f32) -> Option<WholeFrame> {
        let unit = mat
            .to_cols_array()
            .iter()
            .all(|&x| x == 0.0 || x == 1.0 || x == -1.0);
        let small = |x: f32| (1.0..=1024.0).contains(&x) && (x as i32) as f32 == x;
        (unit && small(s) && small(hs)).then(|| WholeFrame {
            axes: [0, 1, 2].map(|k| mat.col(k).as_ivec3()),
            s: s as i32,
            hs: hs as i32,
        })
    }

    /// `v + s (d₁ q_p + d₂ q_{p+1})`: the neighbour at in-plane offset `(d₁, d₂)` of plane
    /// `p`, before clamping.
    #[inline(always)]
    fn neighbour(&self, v: IVec3, p: usize, d1: i32, d2: i32) -> IVec3 {
        v + self.axes[p] * (self.s * d1) + self.axes[(p + 1) % 3] * (self.s * d2)
    }

    /// `qᵀ x · h/s`.
    #[inline(always)]
    fn shift(&self, x: IVec3) -> IVec3 {
        IVec3::new(
            self.axes[0].dot(x),
            self.axes[1].dot(x),
            self.axes[2].dot(x),
        ) * self.hs
    }
}

/// Largest neighbourhood side N (the analysis allows 3..=15).
const MAX_SIDE: usize = 15;

/// When the neighbourhood axes `c₁, c₂` are whole voxel steps along one axis each (the
/// columns of a frame whose entries are 0 and ±1, times a whole scale): `(axis, step)` of
/// each. Then every coordinate of `v + i c₁ + j c₂` is a small integer, exact in `f32`, and
/// its nearest voxel is `v + i a + j b` exactly, with no rounding to do.
#[inline(always)]
fn lattice_steps(c1: Vec3, c2: Vec3) -> Option<((usize, i32), (usize, i32))> {
    let single = |c: Vec3| {
        let i = c.as_ivec3();
        let whole = i.as_vec3() == c && i.abs().cmple(IVec3::splat(1024)).all();
        let axes = (0..3).filter(|&a| i[a] != 0).count();
        (whole && axes == 1).then(|| (0..3).find(|&a| i[a] != 0).map(|a| (a, i[a])))?
    };
    let (a, b) = (single(c1)?, single(c2)?);
    (a.0 != b.0).then_some((a, b))
}

/// Asks for the features of candidate `cand` (a hint only).
#[inline(always)]
fn prefetch_candidate(a: &SolidAnalysisRef, li: usize, weights: [f32; 3], cand: &Triple) {
    for p in 0..3 {
        if weights[p] != 0.0 {
            prefetch_slice(a.feature(li, a.image_of(p), cand.c[p]));
        }
    }
}

/// Candidates whose features are requested ahead of their comparison.
const PREFETCH_AHEAD: usize = 4;

/// A cache hint for the lines of `s`.
#[inline]
fn prefetch_slice(s: &[f32]) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        let p = s.as_ptr() as *const i8;
        let bytes = std::mem::size_of_val(s);
        let mut off = 0;
        while off < bytes {
            // SAFETY: a prefetch is a hint that never faults; the address is inside `s`.
            unsafe { _mm_prefetch(p.add(off), _MM_HINT_T0) };
            off += 64;
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = s;
}

/// `out[k] = basis_k · x − mean_k` for the rows `basis_k` of a row-major basis: each row's dot
/// product is [`dot`]'s, term for term and in the same order (so the same value), but four
/// rows go through the vector at once, which keeps four independent sums in flight where
/// one row at a time waits on its own additions.
#[inline]
fn project(basis: &[f32], x: &[f32], mean: &[f32], out: &mut [f32]) {
    const L: usize = 8;
    let dim = x.len();
    let comps = out.len();
    let whole = dim / L * L;
    let mut k = 0;
    while k + 4 <= comps {
        let rows: [&[f32]; 4] = std::array::from_fn(|r| &basis[(k + r) * dim..(k + r + 1) * dim]);
        let mut acc = [[0.0f32; L]; 4];
        let mut c = 0;
        while c < whole {
            let xs = &x[c..c + L];
            for r in 0..4 {
                let row = &rows[r][c..c + L];
                for i in 0..L {
                    acc[r][i] += row[i] * xs[i];
                }
            }
            c += L;
        }
        for r in 0..4 {
            let mut tail = 0.0f32;
            for i in whole..dim {
                tail += rows[r][i] * x[i];
            }
            out[k + r] = reduce_lanes(acc[r]) + tail - mean[k + r];
        }
        k += 4;
    }
    while k < comps {
        out[k] = dot(&basis[k * dim..(k + 1) * dim], x) - mean[k];
        k += 1;
    }
}

/// The detection tokens, in their own module so that nothing else can build one: their
/// fields are private here.
mod kernels {
    /// Which projection kernels the correction may call. A value of a type whose `AVX2` is true
    /// exists only once the CPU was found to have AVX2, so holding one is what makes the unsafe
    /// calls sound: no safe caller can reach them on a CPU without it.
    pub(super) trait Kernels: Copy {
        const AVX2: bool;
    }

    /// The portable kernels, on any CPU.
    #[derive(Clone, Copy)]
    pub(super) struct Portable;

    impl Kernels for Portable {
        const AVX2: bool = false;
    }

    /// Proof that the CPU has AVX2: only [`Avx2::detect`] makes one.
    #[derive(Clone, Copy)]
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    pub(super) struct Avx2(());

    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    impl Avx2 {
        pub(super) fn detect() -> Option<Avx2> {
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2") {
                return Some(Avx2(()));
            }
            None
        }
    }

    impl Kernels for Avx2 {
        const AVX2: bool = true;
    }

    /// Proof that the CPU has AVX-512F and AVX2: only [`Avx512::detect`] makes one.
    #[derive(Clone, Copy, Debug)]
    pub(super) struct Avx512(());

    impl Avx512 {
        pub(super) fn detect() -> Option<Avx512> {
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx512f")
                && std::arch::is_x86_feature_detected!("avx2")
            {
                return Some(Avx512(()));
            }
            None
        }
    }
}
use kernels::{Avx2, Avx512, Kernels, Portable};

/// [`project`] in AVX registers: lane `i` of row `k`'s register is `project`'s `acc[r][i]`,
/// added to in the same order (a product, then a sum, never fused), so every output is the
/// same bits as [`project`]'s.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn project_avx2(basis: &[f32], x: &[f32], mean: &[f32], out: &mut [f32]) {
    use std::arch::x86_64::{
        _mm256_add_ps, _mm256_loadu_ps, _mm256_mul_ps, _mm256_setzero_ps, _mm256_storeu_ps,
    };
    const L: usize = 8;
    let dim = x.len();
    let comps = out.len();
    assert!(basis.len() >= comps * dim && mean.len() >= comps);
    let whole = dim / L * L;
    let mut k = 0;
    while k + 4 <= comps {
        let rows: [&[f32]; 4] = std::array::from_fn(|r| &basis[(k + r) * dim..(k + r + 1) * dim]);
        let mut acc = [_mm256_setzero_ps(); 4];
        // Raw loads: checked slices cost the loop five compares and branches per eight
        // columns, more than its four multiplies and adds.
        let row_at = rows.map(|r| r.as_ptr());
        let mut c = 0;
        while c < whole {
            // SAFETY: unaligned loads of 8 floats at `c`, where `c + 8 <= whole <= dim`, the
            // length of `x` and of every row.
            let xv = unsafe { _mm256_loadu_ps(x.as_ptr().add(c)) };
            for r in 0..4 {
                // SAFETY: as above.
                let rv = unsafe { _mm256_loadu_ps(row_at[r].add(c)) };
                acc[r] = _mm256_add_ps(acc[r], _mm256_mul_ps(rv, xv));
            }
            c += L;
        }
        for r in 0..4 {
            let mut lanes = [0.0f32; L];
            // SAFETY: an unaligned store of 8 floats to an array of 8.
            unsafe { _mm256_storeu_ps(lanes.as_mut_ptr(), acc[r]) };
            let mut tail = 0.0f32;
            for i in whole..dim {
                tail += rows[r][i] * x[i];
            }
            out[k + r] = reduce_lanes(lanes) + tail - mean[k + r];
        }
        k += 4;
    }
    while k < comps {
        out[k] = dot(&basis[k * dim..(k + 1) * dim], x) - mean[k];
        k += 1;
    }
}

/// The whole 8-column blocks of a row-major `comps × dim` basis, rows taken in pairs: for
/// pair `m` (rows `2m`, `2m + 1`; a last odd row is left out) and block `b`, sixteen floats at
/// `(m · ⌊dim/8⌋ + b) · 16`, row `2m`'s columns `8b..8b + 8` then row `2m + 1`'s: one
/// 512-bit load gives [`project_avx512`] both rows' block.
fn pair_rows(basis: &[f32], dim: usize) -> Vec<f32> {
    let comps = basis.len() / dim.max(1);
    let blocks = dim / 8;
    let mut out = Vec::with_capacity(comps / 2 * blocks * 16);
    for m in 0..comps / 2 {
        for b in 0..blocks {
            for r in [2 * m, 2 * m + 1] {
                out.extend_from_slice(&basis[r * dim + 8 * b..r * dim + 8 * b + 8]);
            }
        }
    }
    out
}

/// [`project`] with two rows in each AVX-512 register: the low eight lanes of pair `m`'s
/// register are row `2m`'s `acc` lanes of [`project`], the high eight row `2m + 1`'s, each
/// added to in the same order (a product, then a sum, never fused) from the same zero, and
/// reduced the same way with the same tail: every output is the same bits as [`project`]'s
/// (which groups rows in fours only to keep sums in flight; a row's value does not depend on
/// its group). Half the multiplies and adds of [`project_avx2`]. `paired` is
/// [`pair_rows`] of `basis`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2")]
fn project_avx512(basis: &[f32], paired: &[f32], x: &[f32], mean: &[f32], out: &mut [f32]) {
    use std::arch::x86_64::{
        _mm256_castps_pd, _mm256_loadu_ps, _mm512_add_ps, _mm512_broadcast_f64x4, _mm512_castpd_ps,
        _mm512_loadu_ps, _mm512_mul_ps, _mm512_setzero_ps, _mm512_storeu_ps,
    };
    const L: usize = 8;
    const GROUP: usize = 4;
    let dim = x.len();
    let comps = out.len();
    let blocks = dim / L;
    let whole = blocks * L;
    let pairs = comps / 2;
    assert!(basis.len() >= comps * dim && mean.len() >= comps);
    assert!(paired.len() >= pairs * blocks * 16);
    // Row `k`'s output from its eight lane sums.
    let finish = |k: usize, lanes: &[f32]| {
        let row = &basis[k * dim..(k + 1) * dim];
        let mut tail = 0.0f32;
        for i in whole..dim {
            tail += row[i] * x[i];
        }
        let acc: [f32; L] = lanes.try_into().expect("8 lanes");
        reduce_lanes(acc) + tail - mean[k]
    };
    let mut m = 0;
    while m < pairs {
        let group = GROUP.min(pairs - m);
        let mut acc = [_mm512_setzero_ps(); GROUP];
        let at = paired.as_ptr();
        for b in 0..blocks {
            // SAFETY: 8 floats of `x` at `8b + 8 <= whole <= dim`; 16 of `paired` at
            // `((m + r) · blocks + b) · 16`, inside its `pairs · blocks · 16` (asserted).
            let xv = unsafe {
                _mm512_castpd_ps(_mm512_broadcast_f64x4(_mm256_castps_pd(_mm256_loadu_ps(
                    x.as_ptr().add(b * L),
                ))))
            };
            for r in 0..group {
                // SAFETY: as above.
                let rv = unsafe { _mm512_loadu_ps(at.add(((m + r) * blocks + b) * 16)) };
                acc[r] = _mm512_add_ps(acc[r], _mm512_mul_ps(rv, xv));
            }
        }
        for r in 0..group {
            let mut lanes = [0.0f32; 16];
            // SAFETY: an unaligned store of 16 floats to an array of 16.
            unsafe { _mm512_storeu_ps(lanes.as_mut_ptr(), acc[r]) };
            let k = 2 * (m + r);
            out[k] = finish(k, &lanes[..L]);
            out[k + 1] = finish(k + 1, &lanes[L..]);
        }
        m += group;
    }
    if comps % 2 == 1 {
        let k = comps - 1;
        out[k] = dot(&basis[k * dim..(k + 1) * dim], x) - mean[k];
    }
}

/// [`lane_sum`]'s final reduction of eight lanes.
#[inline]
fn reduce_lanes(mut acc: [f32; 8]) -> f32 {
    let mut n = 4;
    for i in 0..n {
        acc[i] += acc[i + n];
    }
    while n > 1 {
        for i in 0..n / 2 {
            acc[i] = acc[2 * i] + acc[2 * i + 1];
        }
        n /= 2;
    }
    acc[0]
}

/// Dot product with eight partial sums (see [`lane_sum`]).
#[inline]
fn dot(a: &[f32], b: &[f32]) -> f32 {
    lane_sum::<8>(a, b, |x, y| x * y)
}

/// Squared Euclidean distance with four partial sums (see [`lane_sum`]).
#[inline(always)]
fn squared_distance(a: &[f32], b: &[f32]) -> f32 {
    #[cfg(target_arch = "x86_64")]
    if a.len() == b.len() {
        return squared_distance_sse(a, b);
    }
    squared_distance_portable(a, b)
}

#[inline(always)]
fn squared_distance_portable(a: &[f32], b: &[f32]) -> f32 {
    lane_sum::<4>(a, b, |x, y| {
        let t = x - y;
        t * t
    })
}

/// [`squared_distance_portable`] for equal lengths, its four partial sums in one SSE
/// register (x86-64's baseline): the same operations in the same order, so the same bits.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
#[allow(unused_unsafe)]
fn squared_distance_sse(a: &[f32], b: &[f32]) -> f32 {
    use std::arch::x86_64::{
        _mm_add_ps, _mm_loadu_ps, _mm_mul_ps, _mm_setzero_ps, _mm_storeu_ps, _mm_sub_ps,
    };
    let n = a.len().min(b.len());
    let whole = n / 4 * 4;
    // SAFETY: SSE is part of x86-64; every load and store is of 4 floats from an array of 4.
    let l = unsafe {
        let mut acc = _mm_setzero_ps();
        let mut c = 0;
        while c < whole {
            let x: &[f32; 4] = a[c..c + 4].try_into().expect("4 lanes");
            let y: &[f32; 4] = b[c..c + 4].try_into().expect("4 lanes");
            let d = _mm_sub_ps(_mm_loadu_ps(x.as_ptr()), _mm_loadu_ps(y.as_ptr()));
            acc = _mm_add_ps(acc, _mm_mul_ps(d, d));
            c += 4;
        }
        let mut l = [0.0f32; 4];
        _mm_storeu_ps(l.as_mut_ptr(), acc);
        l
    };
    let mut tail = 0.0f32;
    for i in whole..n {
        let t = a[i] - b[i];
        tail += t * t;
    }
    ((l[0] + l[2]) + (l[1] + l[3])) + tail
}

/// The sum of `term(a[i], b[i])` over `L` partial sums (so it vectorizes), added in a fixed
/// order: lane i with lane i + L/2, then neighbours pairwise (for 8 lanes
/// ((0+4) + (1+5)) + ((2+6) + (3+7))), then the terms past the last whole chunk.
#[inline]
fn lane_sum<const L: usize>(a: &[f32], b: &[f32], term: impl Fn(f32, f32) -> f32) -> f32 {
    let mut acc = [0.0f32; L];
    let (ca, cb) = (a.chunks_exact(L), b.chunks_exact(L));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for i in 0..L {
            acc[i] += term(x[i], y[i]);
        }
    }
    let mut tail = 0.0f32;
    for (x, y) in ra.iter().zip(rb) {
        tail += term(*x, *y);
    }
    let mut n = L / 2;
    for i in 0..n {
        acc[i] += acc[i + n];
    }
    while n > 1 {
        for i in 0..n / 2 {
            acc[i] = acc[2 * i] + acc[2 * i + 1];
        }
        n /= 2;
    }
    acc[0] + tail
}

/// A 64-bit key of a voxel of a level, for counter-based randomness.
fn voxel_key(level: u32, v: IVec3) -> u64 {
    let f = |x: i32| (x as i64 as u64) & 0xF_FFFF;
    ((level as u64) << 60) ^ (f(v.x) << 40) ^ (f(v.y) << 20) ^ f(v.z)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Deterministic floats in [-2, 2) with some exact zeros, negative zeros and repeats.
    fn floats(seed: u64, n: usize) -> Vec<f32> {
        (0..n as u64)
            .map(|i| match counter_hash(seed, 1, i) % 16 {
                0 => 0.0,
                1 => -0.0,
                2 => 1.5,
                _ => 4.0 * counter_unit(seed, 2, i) - 2.0,
            })
            .collect()
    }

    #[test]
    fn avx2_projection_is_bitwise_the_portable_one() {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // N = 7 and 9 neighbourhoods (147, 243 values), and lengths with other tails.
            for (seed, dim, comps) in [
                (1, 243, 20),
                (2, 147, 20),
                (3, 243, 7),
                (4, 8, 3),
                (5, 5, 4),
            ] {
                let basis = floats(seed, dim * comps);
                let x = floats(seed + 100, dim);
                let mean = floats(seed + 200, comps);
                let (mut a, mut b) = (vec![0.0f32; comps], vec![0.0f32; comps]);
                project(&basis, &x, &mean, &mut a);
                // SAFETY: the CPU has AVX2 (checked above).
                unsafe { project_avx2(&basis, &x, &mean, &mut b) };
                let bits = |v: &[f32]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&a), bits(&b), "dim {dim}, comps {comps}");
                // And both are the rows' dot products (so the test compares real values).
                for k in 0..comps {
                    let d: f64 = (0..dim)
                        .map(|i| basis[k * dim + i] as f64 * x[i] as f64)
                        .sum::<f64>()
                        - mean[k] as f64;
                    assert!((a[k] as f64 - d).abs() < 1e-3, "row {k}: {} vs {d}", a[k]);
                }
            }
        }
    }

    #[test]
    fn avx512_projection_is_bitwise_the_portable_one() {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx512f")
            && std::arch::is_x86_feature_detected!("avx2")
        {
            // N = 7 and 9 neighbourhoods, an odd row count, fewer rows than a group, a
            // length under one block, tails of every size.
            for (seed, dim, comps) in [
                (1, 243, 20),
                (2, 147, 20),
                (3, 243, 7),
                (4, 8, 3),
                (5, 5, 4),
                (6, 250, 13),
                (7, 17, 1),
                (8, 64, 18),
            ] {
                let basis = floats(seed, dim * comps);
                let x = floats(seed + 100, dim);
                let mean = floats(seed + 200, comps);
                let paired = pair_rows(&basis, dim);
                let (mut a, mut b) = (vec![0.0f32; comps], vec![0.0f32; comps]);
                project(&basis, &x, &mean, &mut a);
                // SAFETY: the CPU has AVX-512F and AVX2 (checked above).
                unsafe { project_avx512(&basis, &paired, &x, &mean, &mut b) };
                let bits = |v: &[f32]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&a), bits(&b), "dim {dim}, comps {comps}");
            }
        } else {
            // Not a pass: this CPU cannot run the path (CI's emulated CPUs check the others).
            eprintln!("avx512_projection_is_bitwise_the_portable_one: skipped, no AVX-512F");
        }
    }

    #[test]
    fn sse_distance_is_bitwise_the_portable_one() {
        for (seed, n) in [(1, 20), (2, 3), (3, 0), (4, 17), (5, 64)] {
            let (a, b) = (floats(seed, n), floats(seed + 50, n));
            let d = squared_distance(&a, &b);
            assert_eq!(
                d.to_bits(),
                squared_distance_portable(&a, &b).to_bits(),
                "n = {n}"
            );
            let exact: f64 = a
                .iter()
                .zip(&b)
                .map(|(x, y)| (*x as f64 - *y as f64).powi(2))
                .sum();
            assert!((d as f64 - exact).abs() <= 1e-4 * (1.0 + exact), "n = {n}");
        }
    }

    #[test]
    fn whole_frames_give_the_float_paths_values() {
        // The float path of the candidates' shifted pixels, as `correct` computes it.
        let float = |mat: Mat3, s: f32, h: f32, v: IVec3, p: usize, d: (i32, i32)| {
            let (c1, c2) = (mat.col(p) * s, mat.col((p + 1) % 3) * s);
            let wv = round_v(v.as_vec3() + c1 * d.0 as f32 + c2 * d.1 as f32);
            let e = mat.transpose() * ((wv - v).as_vec3() * (h / s));
            (wv, e)
        };
        let frames = [
            Mat3::IDENTITY,
            Mat3::from_cols(-Vec3::Y, Vec3::X, Vec3::Z),
            Mat3::from_cols(Vec3::Y, -Vec3::Z, -Vec3::X),
            Mat3::from_cols(-Vec3::X, -Vec3::Y, Vec3::Z),
        ];
        let mut checked = 0;
        for mat in frames {
            for (s, h) in [
                (1.0f32, 1.0f32),
                (1.0, 8.0),
                (2.0, 4.0),
                (2.0, 2.0),
                (4.0, 8.0),
            ] {
                let f = WholeFrame::of(&mat, s, h / s).expect("a whole frame");
                for v in [
                    IVec3::new(0, 0, 0),
                    IVec3::new(17, 3, 250),
                    IVec3::new(5, 900, 41),
                ] {
                    for p in 0..3 {
                        for d2 in -1..=1 {
                            for d1 in -1..=1 {
                                let (wv, e) = float(mat, s, h, v, p, (d1, d2));
                                assert_eq!(f.neighbour(v, p, d1, d2), wv);
                                // Off the unclamped neighbour too (clamping moves `w`).
                                for w in [wv, wv + IVec3::new(1, -2, 0)] {
                                    let e = if w == wv {
                                        e
                                    } else {
                                        mat.transpose() * ((w - v).as_vec3() * (h / s))
                                    };
                                    let i = f.shift(w - v);
                                    assert_eq!(i, round_v(e), "{mat} s {s} h {h}");
                                    for t in [0u16, 7, 300, 32767] {
                                        for k in 0..3 {
                                            assert_eq!(t as i32 - i[k], round_i(t as f32 - e[k]));
                                        }
                                    }
                                    checked += 1;
                                }
                            }
                        }
                    }
                }
            }
        }
        assert!(checked > 1000);
        // Not whole: a fractional pixel step, a fractional scale, a rotation off the axes.
        assert!(WholeFrame::of(&Mat3::IDENTITY, 3.0, 4.0 / 3.0).is_none());
        assert!(WholeFrame::of(&Mat3::IDENTITY, 1.5, 2.0 / 1.5).is_none());
        let tilted = Mat3::from_quat(glam::Quat::from_rotation_z(0.1));
        assert!(WholeFrame::of(&tilted, 1.0, 1.0).is_none());
        assert!(WholeFrame::of(&(Mat3::IDENTITY * 0.5), 2.0, 1.0).is_none());
    }

    #[test]
    fn lattice_steps_are_the_rounded_positions() {
        let frames = [
            Mat3::IDENTITY,
            Mat3::from_cols(-Vec3::Y, Vec3::X, Vec3::Z),
            Mat3::from_cols(Vec3::Y, -Vec3::Z, -Vec3::X),
        ];
        let mut found = 0;
        for mat in frames {
            for s in [1.0f32, 2.0] {
                for p in 0..3 {
                    let (c1, c2) = (mat.col(p) * s, mat.col((p + 1) % 3) * s);
                    let Some(((ax, sa), (bx, sb))) = lattice_steps(c1, c2) else {
                        continue;
                    };
                    found += 1;
                    assert_ne!(ax, bx);
                    for v in [
                        IVec3::new(0, 0, 0),
                        IVec3::new(1023, 627, 333),
                        IVec3::new(5, 9, 2),
                    ] {
                        let vf = v.as_vec3();
                        for j in -7..=7 {
                            let row = vf + c2 * j as f32;
                            for i in -7..=7 {
                                let mut q = v;
                                q[ax] += sa * i;
                                q[bx] += sb * j;
                                assert_eq!(round_v(row + c1 * i as f32), q);
                            }
                        }
                    }
                }
            }
        }
        // Every plane of these signed permutations, at both scales, is a lattice.
        assert_eq!(found, 18, "{found} lattice planes");
        // A frame off the lattice takes the general path.
        let m = Mat3::from_cols(Vec3::new(0.8, 0.6, 0.0), Vec3::new(-0.6, 0.8, 0.0), Vec3::Z);
        assert!(lattice_steps(m.col(0), m.col(1)).is_none());
        assert!(lattice_steps(Vec3::X * 1.5, Vec3::Y).is_none());
        assert!(lattice_steps(Vec3::X, Vec3::X).is_none());
    }

    #[test]
    fn uniform_fields_look_up_exactly_their_rotation_and_scale() {
        use crate::field::quaternion_field::FieldGrid;
        let grid = FieldGrid::covering(Vec3::new(-1.0, -2.0, 0.5), Vec3::new(3.0, 1.0, 4.0), 7);
        let bits = |q: Quat| q.to_array().map(f32::to_bits);
        // Points inside the grid, on its nodes and cell faces, and outside it.
        let points: Vec<Vec3> = (0..4000u64)
            .map(|i| {
                let u = |a: u64| 8.0 * counter_unit(9, a, i) - 3.0;
                let p = Vec3::new(u(1), u(2), u(3));
                if i % 4 == 0 {
                    (p * 4.0).round() / 4.0
                } else {
                    p
                }
            })
            .collect();
        for scale in [1.0f32, 1.7, 0.3, 2.0, 0.1 + 1e-7] {
            let mut f = RotationField::trivial(grid);
            f.scales.iter_mut().for_each(|s| *s = scale);
            if scale == 1.7 {
                // A negative zero is still the identity.
                f.rotations[3] = Quat::from_xyzw(-0.0, 0.0, -0.0, 1.0);
            }
            assert_eq!(uniform_scale(&f), Some(scale));
            for &p in &points {
                assert_eq!(bits(f.rotation_at(p)), bits(Quat::IDENTITY), "at {p}");
                assert_eq!(f.scale_at(p).to_bits(), scale.to_bits(), "at {p}");
            }
        }
        // Not uniform: one scale differs, one rotation differs, the other sign of the
        // identity (its look-up is −identity), another constant rotation.
        let mut f = RotationField::trivial(grid);
        f.scales[5] = 1.5;
        assert_eq!(uniform_scale(&f), None);
        let mut f = RotationField::trivial(grid);
        f.rotations[5] = Quat::from_rotation_z(0.2);
        assert_eq!(uniform_scale(&f), None);
        let mut f = RotationField::trivial(grid);
        f.rotations.iter_mut().for_each(|q| *q = -Quat::IDENTITY);
        assert_eq!(uniform_scale(&f), None);
        assert_ne!(bits(f.rotation_at(points[1])), bits(Quat::IDENTITY));
        f.rotations
            .iter_mut()
            .for_each(|q| *q = Quat::from_rotation_x(std::f32::consts::FRAC_PI_2));
        assert_eq!(uniform_scale(&f), None);
    }

    #[test]
    fn wrap_without_division_is_rem_euclid() {
        for n in [1u32, 7, 100, 32768] {
            let n_i = n as i32;
            for x in (-3 * n_i..3 * n_i)
                .step_by((n as usize / 50).max(1))
                .chain([-1, 0, n_i - 1, n_i, -n_i, 2 * n_i - 1, 2 * n_i, -n_i - 1])
            {
                assert_eq!(wrap(x, n) as i32, x.rem_euclid(n_i), "x = {x}, n = {n}");
            }
        }
    }
}
