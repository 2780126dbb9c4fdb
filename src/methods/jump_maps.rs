//! Method `jump_maps`: texture coordinates on a mesh from a jump map of the exemplar
//! (Zelinka & Garland, "Interactive Texture Synthesis on Surfaces Using Jump Maps").
//!
//! ```text
//! inputs.exemplar ─ import.exemplar ─ analyse_exemplar (jump map) ───────────┐
//!                                  └──────────────┐                          │
//! inputs.mesh ── import.mesh ── field ── parameterize (order, offsets, boxes) ─ synthesize (walk)
//!                            └───────────────────────────────────────────────── reconstruct ─ files
//! ```
//!
//! `parameterize` reads the exemplar only for its size (to check that triangles fit and for
//! the automatic scale), so a new exemplar of the same size reruns it cheaply and, by early
//! cutoff, nothing downstream on its account.

use super::{MethodError, import};
use crate::artifact::Bundle;
use crate::artifact::jump_maps::{
    JumpParameterization, OrientationField, ParamMeta, ParamParts, TexelAddresses, WalkView,
};
use crate::config::{Config, check_range};
use crate::geom::Mesh;
use crate::image::{Image, ImageView};
use crate::pipeline::FileInput;
use crate::pipeline::{Dag, Handle, NodeContext, NodeError, NodeSpec, Stage};
use crate::stages::analyse_exemplar::jump_map::{
    JumpMap, JumpMapParams, build_jump_map, check_exemplar_size,
};
use crate::stages::field::orientation_field::{FieldParams, orientation_field};
use crate::stages::parameterize::edge_offsets::{
    edge_offsets, largest_fitting_scale, validity_boxes,
};
use crate::stages::parameterize::region_growing::region_growing_order;
use crate::stages::reconstruct::jump_blend::{BlendShader, corner_sets, random_base_set};
use crate::stages::reconstruct::textured_export::{
    ExportParams, ExportSurface, encode_png, export_textured_mesh,
};
use crate::stages::synthesize::jump_walk::{WalkParams, jump_walk};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// Node code versions: bump when a node's output for the same inputs changes.
const JUMP_MAP_VERSION: u32 = 1;
const FIELD_VERSION: u32 = 1;
const PARAMETERIZE_VERSION: u32 = 1;
const WALK_VERSION: u32 = 2;
const RECONSTRUCT_VERSION: u32 = 2;

/// A `jump_maps` config.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct JumpMapsConfig {
    pub method: String,
    pub inputs: Inputs,
    #[serde(default)]
    pub analyse_exemplar: JumpMapParams,
    #[serde(default)]
    pub field: FieldParams,
    #[serde(default)]
    pub parameterize: ParameterizeParams,
    #[serde(default)]
    pub synthesize: WalkParams,
    #[serde(default)]
    pub reconstruct: ExportParams,
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Inputs {
    /// The mesh to texture (.obj, .off, .ply, .stl).
    pub mesh: PathBuf,
    /// The exemplar image (.png, .jpg, .exr).
    pub exemplar: PathBuf,
    /// Further maps aligned with the exemplar (same size), textured with the same
    /// coordinates: `normal`, `roughness`, `height`, or any other name. Default: none.
    #[serde(default)]
    pub maps: BTreeMap<String, PathBuf>,
}

/// `[parameterize]`.
#[derive(Debug, Clone, Default, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct ParameterizeParams {
    /// Texture scale in exemplar texels per object-space unit (§3), or "auto". Default: "auto", so
    /// that the exemplar's width spans a quarter of the mesh's bounding-box diagonal (or less
    /// if the mesh's triangles would not fit).
    pub scale: Scale,
    /// The vertex where region growing starts (§4.1). Default: 0.
    pub seed_vertex: u32,
    /// Turns the exemplar against the field, in degrees counter-clockwise, -360..=360: the
    /// field says where the exemplar's "up" goes, and 90 makes an exemplar's horizontal
    /// features (wood grain, stripes) follow the field instead of crossing it. Default: 0.
    pub rotation: f32,
}

/// `parameterize.scale`: a number of texels per object unit, or "auto".
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(untagged)]
pub enum Scale {
    Texels(f32),
    Auto(AutoWord),
}

/// The word `"auto"`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum AutoWord {
    Auto,
}

impl Default for Scale {
    fn default() -> Self {
        Scale::Auto(AutoWord::Auto)
    }
}

impl ParameterizeParams {
    fn validate(&self) -> Result<(), String> {
        if let Scale::Texels(s) = self.scale
            && !(s.is_finite() && s > 0.0)
        {
            return Err(format!(
                "parameterize.scale must be a positive number of texels per unit, got {s}"
            ));
        }
        if !(self.rotation.is_finite() && (-360.0..=360.0).contains(&self.rotation)) {
            return Err(format!(
                "parameterize.rotation must be in -360..=360 degrees, got {}",
                self.rotation
            ));
        }
        Ok(())
    }
}

pub fn build(config: &Config) -> Result<Dag, MethodError> {
    let c: JumpMapsConfig = config.parse()?;
    let check = |key: &str, r: Result<(), String>| r.map_err(|m| config.invalid(key, &m));
    config.check("analyse_exemplar", c.analyse_exemplar.validate())?;
    check("field", c.field.validate().map_err(|e| e.to_string()))?;
    check("parameterize", c.parameterize.validate())?;
    config.check("synthesize", c.synthesize.validate())?;
    config.check("reconstruct", c.reconstruct.validate())?;
    for name in c.inputs.maps.keys() {
        if name.is_empty()
            || !name
                .chars()
                .all(|ch| ch.is_ascii_alphanumeric() || ch == '_' || ch == '-')
        {
            return Err(config
                .invalid(
                    &format!("inputs.maps.{name}"),
                    "map names may use letters, digits, '_' and '-'",
                )
                .into());
        }
    }

    let mut dag = Dag::default();
    let mesh = import::<Mesh>(
        &mut dag,
        "import.mesh",
        &config.resolve(&c.inputs.mesh),
        "inputs.mesh",
    )?;
    let exemplar_path = config.resolve(&c.inputs.exemplar);
    let exemplar = import::<Image>(
        &mut dag,
        "import.exemplar",
        &exemplar_path,
        "inputs.exemplar",
    )?;
    let exemplar_file = dag.file(&exemplar_path, "inputs.exemplar")?;
    let jump_map = add_jump_map(&mut dag, exemplar, c.analyse_exemplar.clone());

    let field = dag.node(
        NodeSpec::new(Stage::Field, "orientation_field", FIELD_VERSION),
        c.field.clone(),
        mesh,
        |_, p, mesh| {
            Ok(OrientationField(
                orientation_field(&mesh, p).map_err(NodeError::input)?,
            ))
        },
    );

    let param = dag.node(
        NodeSpec::new(Stage::Parameterize, "jump_offsets", PARAMETERIZE_VERSION),
        c.parameterize.clone(),
        (mesh, field, exemplar),
        |_, p, (mesh, up, img)| parameterize(&mesh, up, (img.width, img.height), p),
    );

    let walk = dag.node(
        NodeSpec::new(Stage::Synthesize, "jump_walk", WALK_VERSION),
        c.synthesize.clone(),
        (param, jump_map),
        |ctx, p, (param, jm)| {
            if param.meta.exemplar != (jm.width, jm.height) {
                return Err(NodeError::internal("parameterization and jump map disagree on the exemplar size"));
            }
            let walk = jump_walk(param.walk_input(), jm, p, &|f| ctx.progress.set(f));
            tracing::info!(
                "synthesize: {} vertices, {} jumps, {} random assignments",
                param.order.len(),
                walk.jumps,
                walk.random_assignments
            );
            if walk.random_assignments > 0 {
                tracing::warn!(
                    "synthesize: {} of {} vertices had no valid continuation or jump and got a random address; \
                     a smaller parameterize.scale or a larger exemplar avoids this",
                    walk.random_assignments,
                    param.order.len()
                );
            }
            Ok(TexelAddresses::new(walk, (jm.width, jm.height)))
        },
    );

    let mut maps = Vec::new();
    let mut map_names = Vec::new();
    for (name, path) in &c.inputs.maps {
        let path = config.resolve(path);
        let role = format!("inputs.maps.{name}");
        let img = import::<Image>(&mut dag, &format!("import.map.{name}"), &path, &role)?;
        maps.push((img, dag.file(&path, &role)?));
        map_names.push((name.clone(), extension_of(&path)));
    }

    let params = ReconstructParams {
        export: c.reconstruct.clone(),
        maps: map_names,
        exemplar_format: extension_of(&exemplar_path),
    };
    dag.node(
        NodeSpec::new(Stage::Reconstruct, "jump_blend_export", RECONSTRUCT_VERSION),
        params,
        (mesh, param, walk, exemplar, exemplar_file, maps),
        |ctx, p, (mesh, param, walk, exemplar, exemplar_file, maps)| {
            reconstruct(ctx, p, &mesh, &param, &walk, exemplar, exemplar_file, &maps)
        },
    );
    Ok(dag)
}

/// The jump map of an exemplar (analyse-exemplar, §2 of the 2002 paper); `synth2d` uses the
/// same node, so the two methods share the cached map.
pub(crate) fn add_jump_map(
    dag: &mut Dag,
    exemplar: Handle<Image>,
    params: JumpMapParams,
) -> Handle<JumpMap> {
    dag.node(
        NodeSpec::new(Stage::AnalyseExemplar, "jump_map", JUMP_MAP_VERSION),
        params,
        exemplar,
        |ctx, p, img| {
            check_exemplar_size(img.width, img.height).map_err(NodeError::input)?;
            Ok(build_jump_map(img, p, &|f| ctx.progress.set(f)))
        },
    )
}

/// What the reconstruct node's key holds: the export parameters, each extra map's name and
/// file format, and the exemplar's format (the files are copied into the export as they are).
#[derive(Serialize)]
struct ReconstructParams {
    export: ExportParams,
    maps: Vec<(String, String)>,
    exemplar_format: String,
}

#[allow(clippy::too_many_arguments)]
fn reconstruct(
    ctx: &NodeContext,
    p: &ReconstructParams,
    mesh: &Mesh,
    param: &ParamParts,
    walk: &WalkView,
    exemplar: ImageView,
    exemplar_file: &FileInput,
    maps: &[(ImageView, &FileInput)],
) -> Result<Bundle, NodeError> {
    if walk.addresses.len() != mesh.vertex_count()
        || param.meta.vertices as usize != mesh.vertex_count()
    {
        return Err(NodeError::internal(
            "texel addresses and mesh disagree on the vertex count",
        ));
    }
    let sets = corner_sets(&mesh.triangles, param, walk.addresses).map_err(NodeError::internal)?;
    let single = random_base_set(&sets);
    let mut surfaces = vec![ExportSurface {
        name: "basecolor".into(),
        extension: p.exemplar_format.clone(),
        file: &exemplar_file.bytes,
        shader: BlendShader {
            sets: &sets,
            texture: exemplar,
        },
    }];
    for ((name, ext), (img, file)) in p.maps.iter().zip(maps) {
        if (img.width, img.height) != (exemplar.width, exemplar.height) {
            return Err(NodeError::input(format!(
                "{}: map {name:?} is {}×{}, but the exemplar is {}×{}: maps must be aligned with the exemplar",
                file.path.display(),
                img.width,
                img.height,
                exemplar.width,
                exemplar.height
            )));
        }
        surfaces.push(ExportSurface {
            name: name.clone(),
            extension: ext.clone(),
            file: &file.bytes,
            shader: BlendShader {
                sets: &sets,
                texture: *img,
            },
        });
    }
    let mut files = export_textured_mesh(
        mesh,
        &single,
        (exemplar.width, exemplar.height),
        &surfaces,
        &p.export,
        &|f| ctx.progress.set(f),
    )
    .map_err(NodeError::input)?;
    // Fig. 3 (right) of the paper: the surface textured with a colour ramp instead of the
    // exemplar shows where patches meet.
    let ramp = colour_ramp(exemplar.width, exemplar.height);
    let opts = crate::render::ViewOptions {
        size: p.export.preview_size,
        up: glam::Vec3::from(p.export.up),
        ..Default::default()
    };
    let view = crate::render::render_views(
        mesh,
        &BlendShader {
            sets: &sets,
            texture: ramp.view(),
        },
        &opts,
    );
    files.push(("patches.png".into(), encode_png(&view, false)));
    Ok(Bundle::from(files))
}

fn extension_of(p: &std::path::Path) -> String {
    p.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_else(|| "png".into())
}

/// The texels-per-unit scale at which the exemplar's width spans a quarter of the bounding
/// box diagonal.
fn automatic_scale(mesh: &crate::geom::Mesh, width: u32) -> f32 {
    let (lo, hi) = mesh.bounds();
    let diag = (hi - lo).length();
    if diag > 0.0 && diag.is_finite() {
        width as f32 / (0.25 * diag)
    } else {
        1.0
    }
}

fn parameterize(
    mesh: &crate::geom::Mesh,
    up: &[glam::Vec3],
    (w, h): (u32, u32),
    p: &ParameterizeParams,
) -> Result<JumpParameterization, NodeError> {
    if up.len() != mesh.vertex_count() {
        return Err(NodeError::internal(
            "field and mesh disagree on the vertex count",
        ));
    }
    let n = mesh.vertex_count();
    check_range(
        "parameterize.seed_vertex",
        p.seed_vertex as usize,
        0,
        n.saturating_sub(1),
    )
    .map_err(NodeError::input)?;
    if w < 2 || h < 2 {
        return Err(NodeError::input(format!(
            "the exemplar ({w}×{h}) is too small to texture a surface"
        )));
    }
    let adj = mesh.adjacency();
    let mut scale = match p.scale {
        Scale::Texels(s) => s,
        Scale::Auto(_) => automatic_scale(mesh, w),
    };
    let offsets_at = |scale: f32| {
        let mut o = edge_offsets(mesh, adj, up, scale);
        if p.rotation != 0.0 {
            // Texel y points down, so a counter-clockwise turn on screen is clockwise in
            // (x, y). Negation commutes with the rotation exactly, keeping offsets antisymmetric.
            let (s, c) = (-p.rotation.to_radians()).sin_cos();
            for d in &mut o {
                *d = glam::Vec2::new(c * d.x - s * d.y, s * d.x + c * d.y);
            }
        }
        o
    };
    let mut offsets = offsets_at(scale);
    let mut boxes = validity_boxes(adj, &offsets);
    let fit = largest_fitting_scale(&boxes, scale, w, h);
    if let Scale::Texels(_) = p.scale {
        if fit < scale {
            return Err(NodeError::input(format!(
                "parameterize.scale = {scale} texels per unit is too large for this mesh and a {w}×{h} exemplar: \
                 some triangles do not fit in the exemplar (§1 of the paper). They fit at scale ≤ {fit:.4}; \
                 for good results use at most {:.4}, or refine the mesh",
                0.5 * fit
            )));
        }
        if fit < 2.0 * scale {
            tracing::warn!(
                "parameterize: at scale {scale} some vertex neighbourhoods span more than half the exemplar, \
                 leaving few valid addresses; scale ≤ {:.4} gives the walk more room",
                0.5 * fit
            );
        }
    } else if fit < 2.0 * scale {
        scale = 0.5 * fit;
        tracing::info!(
            "parameterize: automatic scale lowered to {scale} so that triangles fit the exemplar"
        );
        offsets = offsets_at(scale);
        boxes = validity_boxes(adj, &offsets);
    }
    let seed = if (p.seed_vertex as usize) < n {
        p.seed_vertex
    } else {
        0
    };
    let order = region_growing_order(adj, seed);
    Ok(JumpParameterization {
        meta: ParamMeta {
            vertices: n as u64,
            scale,
            exemplar: (w, h),
            components: order.seeds.len() as u32,
        },
        order: order.order,
        seeds: order.seeds,
        adj_offsets: adj.offsets.clone(),
        neighbors: adj.neighbors.clone(),
        edge_offsets: offsets,
        boxes,
    })
}

/// An image whose colour encodes the texel address (red along x, green along y, blue in a
/// checker of 8-texel cells), so a surface textured with it shows its patches.
fn colour_ramp(w: u32, h: u32) -> crate::image::Image {
    let mut img = crate::image::Image::new(w, h);
    for y in 0..h {
        for x in 0..w {
            let checker = ((x / 8 + y / 8) % 2) as f32;
            img.pixels[(y * w + x) as usize] = [
                x as f32 / (w - 1).max(1) as f32,
                y as f32 / (h - 1).max(1) as f32,
                0.25 + 0.5 * checker,
                1.0,
            ];
        }
    }
    img
}
