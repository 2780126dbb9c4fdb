//! Running the planned levels from the coarsest: initialization (§4.1), upsampling (§4.2),
//! the correction steps of each batch over its working values, and the bricks they leave.

use super::SolidSynthesis;
use super::bricks::{Brick, BrickStore, Parents, brick_of, brick_origin};
use super::correction::{States, VoxelState, round_v};
use super::params::SolidError;
use super::plan::{LevelReport, SynthesisReport};
use super::request::VoxelRequest;
use crate::analyse_exemplar::candidate_triples::{Triple, wrap};
use crate::random::{counter_hash, counter_unit};
use crate::synthesize::solid::dependent_set::{CHUNK_VOXELS, ChunkedNeed, chunk_local};
use glam::IVec3;
use rayon::prelude::*;
use std::collections::HashMap;
use std::sync::Arc;
use std::time::Instant;

/// Counter-based random streams: the slab offsets of the initialization, and the upsampling
/// jitter (one stream per axis from this one).
const STREAM_SLAB: u64 = 0x51AB;
const STREAM_JITTER: u64 = 0x7177;

/// A 64-bit key of a voxel of a level, for counter-based randomness.
fn voxel_key(level: u32, v: IVec3) -> u64 {
    let f = |x: i32| (x as i64 as u64) & 0xF_FFFF;
    ((level as u64) << 60) ^ (f(v.x) << 40) ^ (f(v.y) << 20) ^ f(v.z)
}

impl<'a> SolidSynthesis<'a> {
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

    pub(super) fn wh(&self) -> (u32, u32) {
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
}
