//! What a user gets from per-vertex synthesis (Bangay & Morkel, "Graph Matching with
//! Subdivision Surfaces for Texture Synthesis on Surfaces", §3: "Texture synthesis is performed
//! directly on a polygon mesh by assigning a colour directly to each vertex"; §3.5: conversion
//! to a texture map is left to other work; Fig. 10 c/f: the values as displacement).
//!
//! - `textured.ply`: the finest level, triangulated (quads split along their shorter diagonal),
//!   with a colour per vertex; vertex ids are the hierarchy's, so the input's vertices keep
//!   theirs.
//! - `textured.glb`, `textured.obj` + `textured.mtl` and `textured_atlas.png`: the user's own
//!   mesh (the input, before any subdivision) with the finest level's texture baked into an
//!   atlas of its triangles ([`super::finest_level_bake`]: the exemplar read inside each
//!   copied patch, at the atlas's density), what a user opens in any viewer or DCC tool.
//!   With `atlas_size = 0`: `textured.glb` is the finest level with `COLOR_0` (converted to
//!   linear, as glTF wants) and no atlas or OBJ is written.
//! - `preview.png`: three views, drawn by texsyn's rasterizer.
//! - with `displacement > 0`: `displaced.obj` and `displaced.ply`, the finest mesh moved along
//!   its normals by `displacement · (value − 0.5)`, value = the mean of R, G and B (a grey
//!   exemplar is a height map), and `displaced_preview.png` (lit, without colour, so the relief
//!   shows).
//! - with `level_previews`: `level_NN.png`, every level as it was when synthesized, so a
//!   user can see the texture grow.

use super::patch_lookup::ExemplarSampling;
use crate::check::{ParamError, check_range};
use crate::export::encode_png;
use crate::geom::Mesh;
use crate::geom::poly_mesh::PolyMesh;
use crate::render::up_axis::UpAxis;
use crate::render::{ConstantShader, VertexColorShader, ViewOptions, render_views, srgb};
use glam::Vec3;
use serde::{Deserialize, Serialize};
use texsyn_core::algorithm::Failure;

/// The `vertex_colour_export` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("vertex_colour_export", 5);

/// `[reconstruct]` of the graph-matching method.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VertexColourExportParams {
    /// Side of each preview view, 16..=4096. Default: 512.
    pub preview_size: u32,
    /// The mesh's up direction in the previews, or `"auto"` (the default): guessed from the
    /// mesh, the side it stands on most steadily ([`crate::render::up_axis`]). Left out of the
    /// node's key when `"auto"`.
    #[serde(skip_serializing_if = "UpAxis::is_auto")]
    pub up: UpAxis,
    /// Displacement along the normal for a value of 1 (relative to 0.5), in object units,
    /// 0..=1e6; 0 writes no displaced mesh. Default: 0.
    pub displacement: f32,
    /// Also render every level (`level_NN.png`). Default: false.
    pub level_previews: bool,
    /// Side of the atlas the finest level's colours are baked into for the input mesh,
    /// 64..=8192; 0 bakes none (`textured.glb` is then the vertex-coloured finest level).
    /// Default: 2048.
    pub atlas_size: u32,
    /// How the atlas reads the exemplar between texels (inside a copied patch and across seams):
    /// `"bicubic"` (default), `"bilinear"` or `"nearest"` ([`ExemplarSampling`]). Left out of
    /// the node's key at the default.
    #[serde(skip_serializing_if = "ExemplarSampling::is_bicubic")]
    pub lookup: ExemplarSampling,
}

impl Default for VertexColourExportParams {
    fn default() -> Self {
        VertexColourExportParams {
            preview_size: 512,
            up: UpAxis::default(),
            displacement: 0.0,
            level_previews: false,
            atlas_size: 2048,
            lookup: ExemplarSampling::Bicubic,
        }
    }
}

impl VertexColourExportParams {
    pub fn validate(&self) -> Result<(), ParamError> {
        check_range("reconstruct.preview_size", self.preview_size, 16, 4096)?;
        check_range("reconstruct.displacement", self.displacement, 0.0, 1e6)?;
        if self.atlas_size != 0 {
            let most = crate::render::MAX_ATLAS_SIZE;
            check_range("reconstruct.atlas_size", self.atlas_size, 64, most)?;
        }
        self.up
            .check()
            .map_err(|m| ParamError::invalid("reconstruct.up", m))?;
        Ok(())
    }
}

/// What the reconstruct node reads besides its inputs: its parameters and the texture scale
/// (level-0 texels per object unit) the patches were laid at, which the bake continues them
/// with across seams.
#[derive(Debug, Clone, Serialize)]
pub struct ExportKey {
    pub scale: f32,
    pub reconstruct: VertexColourExportParams,
}

/// A level of the hierarchy with its colours (one per vertex of the level).
pub struct ColouredLevel<'a> {
    pub mesh: PolyMesh,
    pub colours: &'a [[f32; 3]],
}

/// Where the finest level's colours were read: per vertex, the exemplar address (NaN where a
/// colour was only interpolated), the exemplar, and the frame each patch was laid in (the
/// field per vertex and `scale` texels per unit).
#[derive(Clone, Copy)]
pub struct CopiedFrom<'a> {
    pub sources: &'a [[f32; 2]],
    pub exemplar: crate::image::ImageView<'a>,
    pub field: &'a [Vec3],
    pub scale: f32,
}

fn rgba(c: &[[f32; 3]]) -> Vec<[f32; 4]> {
    c.iter().map(|c| [c[0], c[1], c[2], 1.0]).collect()
}

/// The output files (see the module doc). `levels` runs coarse to fine; the last is the result;
/// `input` is the user's mesh, which gets the baked atlas.
pub fn export_vertex_colours(
    input: &Mesh,
    levels: &[ColouredLevel],
    copied: Option<CopiedFrom>,
    p: &VertexColourExportParams,
    progress: &dyn Fn(f32),
) -> Vec<(String, Vec<u8>)> {
    let finest = levels.last().expect("at least one level");
    let tri = finest.mesh.to_triangles();
    let colours = rgba(finest.colours);
    let opts = ViewOptions {
        size: p.preview_size,
        // The coarsest level is the input mesh: the same shape, far fewer vertices.
        up: {
            let coarse = levels[0].mesh.to_triangles();
            p.up.resolve(&coarse.positions, &coarse.triangles, "reconstruct")
        },
        ..Default::default()
    };
    let mut files = vec![(
        "textured.ply".to_string(),
        crate::geom::io::write_ply(&tri, Some(&colours)),
    )];
    let atlas = match p.atlas_size {
        0 => None,
        size => crate::render::build_atlas(input, size)
            .inspect_err(|e| {
                tracing::warn!(
                    "reconstruct.atlas_size: {e}; textured.glb carries the finest level's vertex colours (COLOR_0) instead of a baked atlas of the input mesh"
                )
            })
            .ok(),
    };
    match atlas {
        Some(atlas) => {
            let normals = finest.mesh.vertex_normals();
            let lookup = copied.map(|c| {
                super::finest_level_bake::finest_lookup(
                    &tri, &normals, c.field, c.scale, c.sources, c.exemplar, p.lookup,
                )
            });
            if let Some(l) = &lookup {
                tracing::info!(
                    "atlas: {:.1} % of the finest level's triangles lie in one copied patch and read the exemplar; across the rest each corner's patch is continued and blended",
                    100.0 * l.looked_up_share()
                );
            }
            let shader =
                super::finest_level_bake::FinestColours::new(input, &tri, finest.colours, lookup);
            let png = encode_png(&crate::render::bake(&atlas, input, &shader), false);
            let glb = super::textured_export::per_triangle_atlas_glb(
                "graph_matching",
                input,
                &atlas,
                &png,
            );
            let uv: Vec<[glam::Vec2; 3]> = (atlas.corner_uv.iter())
                .map(|t| t.map(|q| glam::Vec2::new(q.x, 1.0 - q.y)))
                .collect();
            let obj = crate::export::write_obj(input, Some(&uv), Some("textured.mtl"), "texsyn");
            let maps = crate::export::obj::MtlMaps {
                diffuse: Some("textured_atlas.png".into()),
                ..Default::default()
            };
            files.push(("textured.glb".into(), glb));
            files.push(("textured.obj".into(), obj.into_bytes()));
            files.push((
                "textured.mtl".into(),
                crate::export::obj::write_mtl("texsyn", &maps).into_bytes(),
            ));
            files.push(("textured_atlas.png".into(), png));
        }
        None => files.push(("textured.glb".to_string(), glb(&tri, &colours))),
    }
    progress(0.2);
    let preview = render_views(
        &tri,
        &VertexColorShader::new(&tri.triangles, &colours),
        &opts,
    );
    files.push(("preview.png".into(), encode_png(&preview, false)));
    progress(0.5);
    if p.displacement > 0.0 {
        let displaced = displace(&tri, finest.colours, p.displacement);
        files.push((
            "displaced.obj".into(),
            crate::export::write_obj(&displaced, None, None, "displaced").into_bytes(),
        ));
        files.push((
            "displaced.ply".into(),
            crate::geom::io::write_ply(&displaced, Some(&colours)),
        ));
        let shaded = render_views(&displaced, &ConstantShader(Vec3::splat(0.8)), &opts);
        files.push(("displaced_preview.png".into(), encode_png(&shaded, false)));
    }
    if p.level_previews {
        for (l, level) in levels.iter().enumerate() {
            let t = level.mesh.to_triangles();
            let c = rgba(level.colours);
            let img = render_views(&t, &VertexColorShader::new(&t.triangles, &c), &opts);
            files.push((format!("level_{l:02}.png"), encode_png(&img, false)));
            progress(0.5 + 0.5 * (l + 1) as f32 / levels.len() as f32);
        }
    }
    progress(1.0);
    files
}

/// The mesh moved along its normals by `height · (mean(RGB) − 0.5)`.
pub fn displace(mesh: &Mesh, values: &[[f32; 3]], height: f32) -> Mesh {
    let normals = mesh.vertex_normals();
    let positions = mesh
        .positions
        .iter()
        .zip(normals)
        .zip(values)
        .map(|((p, n), c)| *p + *n * (height * ((c[0] + c[1] + c[2]) / 3.0 - 0.5)))
        .collect();
    Mesh::new(positions, mesh.triangles.clone())
}

fn glb(mesh: &Mesh, colours: &[[f32; 4]]) -> Vec<u8> {
    let linear = colours
        .iter()
        .map(|c| {
            [
                srgb::to_linear(c[0]),
                srgb::to_linear(c[1]),
                srgb::to_linear(c[2]),
                1.0,
            ]
        })
        .collect();
    let scene = crate::export::GlbMesh {
        name: "graph_matching".into(),
        positions: mesh.positions.clone(),
        normals: mesh.vertex_normals().to_vec(),
        colors: Some(linear),
        indices: mesh.triangles.iter().flatten().copied().collect(),
        material: crate::export::GlbMaterial {
            double_sided: true,
            ..Default::default()
        },
        ..Default::default()
    };
    crate::export::write_glb(&scene)
}

/// The reconstruct node: every level of the hierarchy with its colours (`level_colours`: all
/// levels' vertices, coarsest first), exported, and the finest baked onto `input`.
pub fn node(
    input: &Mesh,
    h: &crate::parameterize::sqrt2_subdivision::Sqrt2Hierarchy,
    level_colours: &[[f32; 3]],
    copied: Option<CopiedFrom>,
    p: &VertexColourExportParams,
    progress: &dyn Fn(f32),
) -> Result<Vec<(String, Vec<u8>)>, Failure> {
    let mut start = 0;
    let mut levels = Vec::new();
    for l in 0..h.levels() {
        let n = h.level_vertices[l] as usize;
        let colours = level_colours
            .get(start..start + n)
            .ok_or_else(|| Failure::internal("colours and hierarchy disagree"))?;
        levels.push(ColouredLevel {
            mesh: h.level(l),
            colours,
        });
        start += n;
    }
    let finest = levels.last().map_or(0, |l| l.colours.len());
    if let Some(c) = copied
        && (c.sources.len() != finest || c.field.len() < finest)
    {
        return Err(Failure::internal("sources and the finest level disagree"));
    }
    Ok(export_vertex_colours(input, &levels, copied, p, progress))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn displacement_moves_vertices_along_normals_by_their_value() {
        let m = crate::geom::primitives::grid(3, 1.0);
        let n = m.vertex_normals()[4];
        let values: Vec<[f32; 3]> = (0..9)
            .map(|v| if v == 4 { [1.0; 3] } else { [0.5; 3] })
            .collect();
        let d = displace(&m, &values, 2.0);
        assert!((d.positions[4] - (m.positions[4] + n)).length() < 1e-6);
        assert_eq!(d.positions[0], m.positions[0]);
    }
}
