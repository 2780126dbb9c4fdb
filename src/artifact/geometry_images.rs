//! Artifact formats of the geometry-image method: geometry images, texel images and the
//! parameter-domain field.

use super::{Artifact, ArtifactError, ArtifactWriter, Kind};
use crate::geom::geometry_image::{GeometryImage, TexelImage};
use crate::stages::field::param_field::ParamField;
use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};

fn bad(msg: &str) -> ArtifactError {
    ArtifactError::Meta(msg.into())
}

pub fn write_geometry_image(gi: &GeometryImage) -> Vec<u8> {
    ArtifactWriter::new(Kind::GeometryImage, &gi.n)
        .array("positions", &gi.positions)
        .array("normals", &gi.normals)
        .array("mate_rep", &gi.mate_rep)
        .finish()
}

/// Reads a geometry image (copied: synthesis and reconstruction want owned grids).
pub fn read_geometry_image(a: &Artifact) -> Result<GeometryImage, ArtifactError> {
    a.expect_kind(Kind::GeometryImage)?;
    let n: u32 = a.meta()?;
    let count = n as usize * n as usize;
    let positions: &[Vec3] = a.array("positions")?;
    let normals: &[Vec3] = a.array("normals")?;
    let mate_rep: &[u32] = a.array("mate_rep")?;
    if positions.len() != count || normals.len() != count || mate_rep.len() != count {
        return Err(bad("geometry image arrays disagree with its size"));
    }
    if mate_rep
        .iter()
        .enumerate()
        .any(|(k, &r)| r as usize > k || mate_rep[r as usize] != r)
    {
        return Err(bad("geometry image mate table is inconsistent"));
    }
    Ok(GeometryImage {
        n,
        positions: positions.to_vec(),
        normals: normals.to_vec(),
        mate_rep: mate_rep.to_vec(),
    })
}

/// Metadata of a texel image: its size and channels, and the sample's texel spacing in
/// object units (texel values are stored divided by it, see `stages::reconstruct::displacement`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct TexelMeta {
    pub width: u32,
    pub height: u32,
    pub channels: u32,
}

pub fn write_texels(t: &TexelImage) -> Vec<u8> {
    ArtifactWriter::new(
        Kind::TexelImage,
        &TexelMeta {
            width: t.width,
            height: t.height,
            channels: t.channels,
        },
    )
    .array("data", &t.data)
    .finish()
}

pub fn read_texels(a: &Artifact) -> Result<TexelImage, ArtifactError> {
    a.expect_kind(Kind::TexelImage)?;
    let m: TexelMeta = a.meta()?;
    let data: &[f32] = a.array("data")?;
    if data.len() != m.width as usize * m.height as usize * m.channels as usize
        || !(m.channels == 3 || m.channels == 6)
    {
        return Err(bad("texel image size disagrees with its metadata"));
    }
    Ok(TexelImage {
        width: m.width,
        height: m.height,
        channels: m.channels,
        data: data.to_vec(),
    })
}

pub fn write_param_field(f: &ParamField) -> Vec<u8> {
    ArtifactWriter::new(Kind::ParamField, &(f.dir.len() as u64))
        .array("dir", &f.dir)
        .array("rel_scale", &f.rel_scale)
        .finish()
}

pub fn read_param_field(a: &Artifact) -> Result<ParamField, ArtifactError> {
    a.expect_kind(Kind::ParamField)?;
    let n: u64 = a.meta()?;
    let dir: &[Vec2] = a.array("dir")?;
    let rel_scale: &[f32] = a.array("rel_scale")?;
    if dir.len() as u64 != n || rel_scale.len() as u64 != n {
        return Err(bad("field arrays disagree with its metadata"));
    }
    Ok(ParamField {
        dir: dir.to_vec(),
        rel_scale: rel_scale.to_vec(),
    })
}
