//! Bricks, the unit of storage and of caching: the final triples of one dual cell of one
//! level, where they live ([`BrickStore`], [`MemoryBrickStore`]), and the look-up of parent
//! triples in the bricks of the level below.

use super::params::SolidError;
use crate::analyse_exemplar::candidate_triples::Triple;
use glam::IVec3;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

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
    pub(super) fn at(&self, local: IVec3) -> Triple {
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

/// The parents' bricks of a level.
pub(super) struct Parents {
    pub(super) m: i32,
    pub(super) bricks: HashMap<[i32; 3], Arc<Brick>>,
}

impl Parents {
    #[inline]
    pub(super) fn get(&self, v: IVec3) -> Triple {
        let b = brick_of(self.m, v);
        let local = v - brick_origin(self.m, b);
        self.bricks[&<[i32; 3]>::from(b)].at(local)
    }
}

#[inline]
pub(super) fn brick_of(m: i32, v: IVec3) -> IVec3 {
    (v - IVec3::splat(m / 2)).div_euclid(IVec3::splat(m))
}

#[inline]
pub(super) fn brick_origin(m: i32, b: IVec3) -> IVec3 {
    b * m + IVec3::splat(m / 2)
}
