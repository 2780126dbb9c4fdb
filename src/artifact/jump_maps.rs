//! Artifact formats of the jump-map method: the jump map, the orientation field, the
//! parameterization (order, edge offsets, validity boxes) and the walk's texel addresses.
//! Each is a few raw arrays viewed in place; readers check lengths against each other so a
//! damaged artifact is an error, never an out-of-bounds index later.

use super::{Artifact, ArtifactError, ArtifactWriter, Format, Kind};
use crate::stages::analyse_exemplar::jump_map::{Jump, JumpMap, JumpMapRef};
pub use crate::stages::parameterize::edge_offsets::{OffsetBox, ParamMeta, ParamParts};
use crate::stages::synthesize::jump_walk::Walk;
use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};

fn bad(msg: impl Into<String>) -> ArtifactError {
    ArtifactError::Meta(msg.into())
}

#[derive(Serialize, Deserialize)]
struct JumpMapMeta {
    width: u32,
    height: u32,
    k: u32,
}

impl Format for JumpMap {
    const KIND: Kind = Kind::JumpMap;
    type View<'a> = JumpMapRef<'a>;
    fn write(&self) -> Vec<u8> {
        write_jump_map(self)
    }
    fn decode(a: &Artifact) -> Result<JumpMapRef<'_>, ArtifactError> {
        view_jump_map(a)
    }
}

/// The per-vertex "up" directions of the orientation field (§3).
pub struct OrientationField(pub Vec<Vec3>);

impl Format for OrientationField {
    const KIND: Kind = Kind::OrientationField;
    type View<'a> = &'a [Vec3];
    fn write(&self) -> Vec<u8> {
        write_field(&self.0)
    }
    fn decode(a: &Artifact) -> Result<&[Vec3], ArtifactError> {
        view_field(a)
    }
}

pub fn write_jump_map(jm: &JumpMap) -> Vec<u8> {
    ArtifactWriter::new(
        Kind::JumpMap,
        &JumpMapMeta {
            width: jm.width,
            height: jm.height,
            k: jm.k,
        },
    )
    .array("jumps", &jm.jumps)
    .finish()
}

pub fn view_jump_map(a: &Artifact) -> Result<JumpMapRef<'_>, ArtifactError> {
    a.expect_kind(Kind::JumpMap)?;
    let m: JumpMapMeta = a.meta()?;
    let jumps: &[Jump] = a.array("jumps")?;
    JumpMapRef::new(m.width, m.height, m.k, jumps).map_err(|e| bad(e.to_string()))
}

pub fn write_field(up: &[Vec3]) -> Vec<u8> {
    ArtifactWriter::new(Kind::OrientationField, &(up.len() as u64))
        .array("up", up)
        .finish()
}

pub fn view_field(a: &Artifact) -> Result<&[Vec3], ArtifactError> {
    a.expect_kind(Kind::OrientationField)?;
    let n: u64 = a.meta()?;
    let up: &[Vec3] = a.array("up")?;
    if up.len() as u64 != n {
        return Err(bad("field length disagrees with metadata"));
    }
    Ok(up)
}

/// The parameterization as its node computes it; [`ParamParts`] is how readers see it.
pub struct JumpParameterization {
    pub meta: ParamMeta,
    pub order: Vec<u32>,
    pub seeds: Vec<u32>,
    pub adj_offsets: Vec<u32>,
    pub neighbors: Vec<u32>,
    pub edge_offsets: Vec<Vec2>,
    pub boxes: Vec<OffsetBox>,
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

pub fn write_parameterization(p: &ParamParts) -> Vec<u8> {
    ArtifactWriter::new(Kind::JumpParameterization, &p.meta)
        .array("order", p.order)
        .array("seeds", p.seeds)
        .array("adj_offsets", p.adj_offsets)
        .array("neighbors", p.neighbors)
        .array("edge_offsets", p.edge_offsets)
        .array("boxes", p.boxes)
        .finish()
}

pub fn view_parameterization(a: &Artifact) -> Result<ParamParts<'_>, ArtifactError> {
    a.expect_kind(Kind::JumpParameterization)?;
    let p = ParamParts {
        meta: a.meta()?,
        order: a.array("order")?,
        seeds: a.array("seeds")?,
        adj_offsets: a.array("adj_offsets")?,
        neighbors: a.array("neighbors")?,
        edge_offsets: a.array("edge_offsets")?,
        boxes: a.array("boxes")?,
    };
    let n = p.meta.vertices as usize;
    let ok = p.boxes.len() == n
        && p.adj_offsets.len() == n + 1
        && p.adj_offsets.first() == Some(&0)
        && p.adj_offsets.windows(2).all(|w| w[0] <= w[1])
        && *p.adj_offsets.last().unwrap() as usize == p.neighbors.len()
        && p.edge_offsets.len() == p.neighbors.len()
        && p.neighbors.iter().all(|&v| (v as usize) < n)
        && p.order.iter().all(|&v| (v as usize) < n)
        && p.order.len() <= n
        && p.seeds.iter().all(|&s| (s as usize) < p.order.len().max(1));
    if !ok {
        return Err(bad("parameterization arrays are inconsistent"));
    }
    Ok(p)
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct WalkMeta {
    pub vertices: u64,
    pub jumps: u64,
    pub random_assignments: u64,
    pub exemplar: (u32, u32),
}

pub fn write_walk(walk: &Walk, exemplar: (u32, u32)) -> Vec<u8> {
    ArtifactWriter::new(
        Kind::TexelAddresses,
        &WalkMeta {
            vertices: walk.addresses.len() as u64,
            jumps: walk.jumps,
            random_assignments: walk.random_assignments,
            exemplar,
        },
    )
    .array("addresses", &walk.addresses)
    .array("patches", &walk.patches)
    .finish()
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

crate::format_pair! {
    TexelAddresses => WalkView, kind: TexelAddresses, meta: meta,
    arrays: [addresses, patches],
    check: |v| v.addresses.len() as u64 == v.meta.vertices && v.patches.len() == v.addresses.len(),
}

pub struct WalkView<'a> {
    pub meta: WalkMeta,
    pub addresses: &'a [Vec2],
    pub patches: &'a [u32],
}

pub fn view_walk(a: &Artifact) -> Result<WalkView<'_>, ArtifactError> {
    a.expect_kind(Kind::TexelAddresses)?;
    let v = WalkView {
        meta: a.meta()?,
        addresses: a.array("addresses")?,
        patches: a.array("patches")?,
    };
    if v.addresses.len() as u64 != v.meta.vertices || v.patches.len() != v.addresses.len() {
        return Err(bad("texel address arrays disagree with metadata"));
    }
    Ok(v)
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
