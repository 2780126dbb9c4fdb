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
//!   with the local frame, are gathered from the level's voxels (trilinear or nearest, per
//!   level), each voxel showing in plane `P`'s neighbourhood its own texel in `P` (or, with
//!   `neighbourhood_colour = "mean"`, its colour), each projected on its plane's PCA basis, and compared with the candidates
//!   `S(v)` in the reduced form: for plane `P` and `d ∈ {−1, 0, 1}²` in `P`, the voxel
//!   `w = [v + s q_v d]` and its coordinate `T_P(w)` shifted back by `w`'s exemplar offset
//!   `h_l P(q_v⁻¹ (w − v) / s)` names an exemplar pixel whose `k` candidate triples join the
//!   set. The candidate with the least plane-weighted squared distance in PCA space wins
//!   (ties: the first visited, planes xy, yz, zx, then `d` row by row). A voxel's colour is
//!   the plane-weighted mean of its triple's three stack texels at the level (the plain
//!   average by default); planes of weight 0 are neither gathered nor matched.
//! - **Subpasses and barriers** (§4.3.1, §5.2–5.3): a level's corrections are a [`Schedule`] of
//!   stages and steps with history windows ([`HistoryWindow`], `history_window.rs`): plain
//!   correction, grid correction (barriers at the `M`-cells) or dual-grid correction (`⌈P/2⌉`
//!   grid passes then `⌊P/2⌋` passes behind the dual lattice, offset `M/2`).
//!
//! [`HistoryWindow`]: crate::synthesize::solid::history_window::HistoryWindow
//! [`Triple`]: crate::analyse_exemplar::candidate_triples::Triple
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
//! - §4.3 gathers "the color of voxels" into the three neighbourhoods, a voxel's colour being
//!   the mean of its three texels. By default (`neighbourhood_colour = "plane"`,
//!   [`NeighbourhoodColour`]) a voxel shows, in the neighbourhood of plane `P`, its own texel
//!   in `P`: each plane is compared with what a cut along `P` holds, not with an average of
//!   three unrelated texels wherever a triple is not consistent (which blurred sections:
//!   README, "Solid: what a voxel shows"). The reconstruct node shows the facing planes'
//!   texels to match (`stages/reconstruct/solid_colour.rs`).
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
//! - With a feature mask (`analyse_exemplar.feature_mask`) matching reads appearance-space
//!   texels ([`SolidAnalysisRef::match_texel`], or [`SolidAnalysisRef::match_colour`] for
//!   the mean); what is output stays the colour.
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
//!   `stencil_reach` in `plan.rs`); the paper's `D = ⌈N√2⌉`. For the trivial field it is only the
//!   squares of the weighted exemplar planes ([`Stencil`]), which is all a correction reads.
//!
//! # Files
//!
//! This file holds the configured synthesis and its accessors; `params.rs` the parameters,
//! the pyramid and the errors; `request.rs` the voxel requests; `bricks.rs` the bricks and
//! their stores; `plan.rs` the planning of a request into levels and batches, and the
//! reports; `run.rs` the levels' initialization, upsampling and correction steps;
//! `correction.rs` the correction of one voxel. Its numeric kernels (projections, distances,
//! their SIMD versions) are `texsyn_core::simd`.

mod bricks;
mod correction;
mod params;
mod plan;
mod request;
mod run;
mod shard;

pub use bricks::{Brick, BrickMeta, BrickStore, MemoryBrickStore};
pub use params::{
    LevelParams, NeighbourhoodColour, Pyramid, Scheme, SolidError, SolidParams, coarse_level,
    couple_levels,
};
pub use plan::{BatchLimits, LevelDependency, LevelReport, SynthesisReport};
pub use request::VoxelRequest;
pub use shard::{BrickShare, synthesize_share};

use bricks::{brick_of, brick_origin};
use plan::{stencil_reach, widen_for_integration};

use crate::analyse_exemplar::candidate_triples::SolidAnalysisRef;
use crate::field::coarse_field_smoothing::smooth_field;
use crate::field::quaternion_field::RotationField;
use crate::parameterize::volume_embedding::Volume;
use crate::simd::{Avx512, pair_rows};
use crate::synthesize::solid::dependent_set::Stencil;
use crate::synthesize::solid::history_window::Schedule;
use glam::{IVec3, Quat, Vec3};

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
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analyse_exemplar::candidate_triples::wrap;
    use crate::random::counter_unit;

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
