//! Artifact formats of the jump-map methods: the jump map, the orientation field, the
//! parameterization (order, edge offsets, validity boxes), the walk's texel addresses and
//! `synth2d`'s address image. Each is a few raw arrays viewed in place; readers check lengths
//! against each other so a damaged artifact is an error, never an out-of-bounds index later.

use super::format::inconsistent;
use super::{AlignedBytes, Artifact, ArtifactError, ArtifactWriter, Format, Kind};
use crate::stages::analyse_exemplar::jump_map::{Jump, JumpMap, JumpMapRef};
pub use crate::stages::parameterize::jump_parameterization::{
    JumpParameterization, ParamMeta, ParamParts,
};
use crate::stages::synthesize::jump_walk::Walk;
use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};

#[derive(Serialize, Deserialize)]
struct JumpMapMeta {
    width: u32,
    height: u32,
    k: u32,
}

impl Format for JumpMap {
    const KIND: Kind = Kind::JumpMap;
    type View<'a> = JumpMapRef<'a>;
    fn write(&self) -> AlignedBytes {
        let meta = JumpMapMeta {
            width: self.width,
            height: self.height,
            k: self.k,
        };
        ArtifactWriter::new(Self::KIND, &meta)
            .array("jumps", &self.jumps)
            .finish()
    }
    fn decode(a: &Artifact) -> Result<JumpMapRef<'_>, ArtifactError> {
        let m: JumpMapMeta = a.meta()?;
        let jumps: &[Jump] = a.array("jumps")?;
        JumpMapRef::new(m.width, m.height, m.k, jumps).map_err(|e| inconsistent(e.to_string()))
    }
}

/// The per-vertex "up" directions of the orientation field (§3).
pub struct OrientationField(pub Vec<Vec3>);

impl Format for OrientationField {
    const KIND: Kind = Kind::OrientationField;
    type View<'a> = &'a [Vec3];
    fn write(&self) -> AlignedBytes {
        ArtifactWriter::new(Self::KIND, &(self.0.len() as u64))
            .array("up", &self.0)
            .finish()
    }
    fn decode(a: &Artifact) -> Result<&[Vec3], ArtifactError> {
        let n: u64 = a.meta()?;
        let up: &[Vec3] = a.array("up")?;
        if up.len() as u64 != n {
            return Err(inconsistent("field length disagrees with metadata"));
        }
        Ok(up)
    }
}

crate::format_pair! {
    JumpParameterization => ParamParts, kind: JumpParameterization, meta: meta,
    arrays: [order, seeds, adj_offsets, neighbors, edge_offsets, boxes],
    check: |p| parameterization_is_consistent(p),
}

fn parameterization_is_consistent(p: &ParamParts) -> bool {
    let n = p.meta.vertices as usize;
    p.boxes.len() == n
        && p.adj_offsets.len() == n + 1
        && p.adj_offsets.first() == Some(&0)
        && p.adj_offsets.windows(2).all(|w| w[0] <= w[1])
        && *p.adj_offsets.last().unwrap() as usize == p.neighbors.len()
        && p.edge_offsets.len() == p.neighbors.len()
        && p.neighbors.iter().all(|&v| (v as usize) < n)
        && p.order.iter().all(|&v| (v as usize) < n)
        && p.order.len() <= n
        && p.seeds.iter().all(|&s| (s as usize) < p.order.len().max(1))
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct WalkMeta {
    pub vertices: u64,
    pub jumps: u64,
    pub random_assignments: u64,
    pub exemplar: (u32, u32),
}

/// The walk's texel addresses as stored, with the exemplar size they address.
pub struct TexelAddresses {
    pub meta: WalkMeta,
    pub addresses: Vec<Vec2>,
    pub patches: Vec<u32>,
}

impl TexelAddresses {
    pub fn new(walk: Walk, exemplar: (u32, u32)) -> TexelAddresses {
        TexelAddresses {
            meta: WalkMeta {
                vertices: walk.addresses.len() as u64,
                jumps: walk.jumps,
                random_assignments: walk.random_assignments,
                exemplar,
            },
            addresses: walk.addresses,
            patches: walk.patches,
        }
    }
}

pub struct WalkView<'a> {
    pub meta: WalkMeta,
    pub addresses: &'a [Vec2],
    pub patches: &'a [u32],
}

crate::format_pair! {
    TexelAddresses => WalkView, kind: TexelAddresses, meta: meta,
    arrays: [addresses, patches],
    check: |v| v.addresses.len() as u64 == v.meta.vertices && v.patches.len() == v.addresses.len(),
}

/// The image jump-map synthesis of `synth2d`: one exemplar texel address per output pixel.
pub struct AddressImage {
    /// Width and height in pixels.
    pub size: (u32, u32),
    pub addresses: Vec<[u16; 2]>,
}

pub struct AddressImageRef<'a> {
    pub size: (u32, u32),
    pub addresses: &'a [[u16; 2]],
}

crate::format_pair! {
    AddressImage => AddressImageRef, kind: AddressImage, meta: size,
    arrays: [addresses],
    check: |a| a.addresses.len() == a.size.0 as usize * a.size.1 as usize,
}
