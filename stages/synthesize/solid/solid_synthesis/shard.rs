//! One shard's share of a solid synthesis (`texsyn run --shard`): the finest bricks a shard
//! is assigned among those the request touches, and the coarser bricks they depend on.

use super::bricks::BrickStore;
use super::plan::LevelReport;
use super::request::VoxelRequest;
use super::{SolidError, SolidSynthesis};
use serde::Serialize;
use std::collections::HashSet;
use texsyn_core::algorithm::Failure;

/// Picks a shard's part of all finest bricks (sorted).
pub type Assign<'a> = &'a dyn Fn(&[[i32; 3]]) -> Vec<[i32; 3]>;

/// What a shard did (or, planning, would do).
#[derive(Debug, Serialize)]
pub struct BrickShare {
    /// The finest bricks of the whole request, over all shards.
    pub finest_bricks: usize,
    /// This shard's finest bricks, sorted.
    pub assigned: Vec<[i32; 3]>,
    /// Bricks needed, computed and reused per level, coarsest first (planning: what a run
    /// would compute with the cache as it is).
    pub levels: Vec<LevelReport>,
    /// Planning only: the bricks per level the share depends on, all computed from an empty
    /// cache (what a shard on its own machine, sharing nothing, computes).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub from_empty_cache: Option<Vec<usize>>,
}

/// Synthesizes (or, with `plan_only`, plans) into `store` the bricks of the voxels among
/// `voxels` whose finest brick `assign` gives this shard (`assign` picks a shard's part of
/// all finest bricks, sorted).
pub fn synthesize_share(
    synth: &SolidSynthesis,
    voxels: &[[i32; 3]],
    store: &dyn BrickStore,
    assign: Assign,
    plan_only: bool,
) -> Result<BrickShare, Failure> {
    let all = synth.request_bricks(&VoxelRequest::from_voxels(voxels));
    let assigned = assign(&all);
    let mine: HashSet<[i32; 3]> = assigned.iter().copied().collect();
    let share: Vec<[i32; 3]> = voxels
        .iter()
        .filter(|v| mine.contains(&synth.brick_of(**v)))
        .copied()
        .collect();
    let request = VoxelRequest::from_voxels(&share);
    let (levels, from_empty_cache) = if plan_only {
        let fresh = synth.bricks_needed(&request).iter().map(Vec::len).collect();
        (synth.plan_report(&request, store), Some(fresh))
    } else {
        let report = synth.synthesize(&request, store);
        let report = report.map_err(|e| Failure::classify(e, SolidError::is_internal))?;
        (report.levels, None)
    };
    Ok(BrickShare {
        finest_bricks: all.len(),
        assigned,
        levels,
        from_empty_cache,
    })
}
