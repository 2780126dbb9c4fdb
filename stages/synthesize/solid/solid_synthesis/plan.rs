//! Planning a request: the bricks it needs level by level (the dependent set worked backwards
//! from the finest level), the missing ones in batches within [`BatchLimits`], the stencil
//! reach the sets dilate by, and the reports of what was planned and done.

use super::SolidSynthesis;
use super::bricks::{BrickStore, brick_of, brick_origin};
use super::params::{Pyramid, SolidParams};
use super::request::VoxelRequest;
use crate::analyse_exemplar::candidate_triples::SolidAnalysisRef;
use crate::field::quaternion_field::RotationField;
use crate::synthesize::solid::dependent_set::{
    CHUNK_VOXELS, ChunkedNeed, NeedGrid, chunk_local, dependent_box, dependent_set,
};
use glam::{IVec3, Mat3};
use serde::Serialize;
use std::collections::BTreeSet;

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

/// One planned level: its needed and missing bricks, the missing ones in batches.
pub(super) struct LevelPlan {
    pub(super) needed: Vec<[i32; 3]>,
    pub(super) missing: Vec<[i32; 3]>,
    pub(super) batches: Vec<Batch>,
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
pub(super) struct Batch {
    pub(super) bricks: Vec<[i32; 3]>,
    pub(super) need: ChunkedNeed,
    /// Bricks of the level below holding the parents of `need`'s voxels.
    pub(super) parents: Vec<[i32; 3]>,
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
/// synthesizing it holds two `VoxelState`s of 24 bytes per working voxel
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
pub(super) fn stencil_reach(
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
pub(super) fn widen_for_integration(
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

impl<'a> SolidSynthesis<'a> {
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
    pub(super) fn plan(
        &self,
        request: &VoxelRequest,
        store: Option<&dyn BrickStore>,
    ) -> Vec<LevelPlan> {
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
}
