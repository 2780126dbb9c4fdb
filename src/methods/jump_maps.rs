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

use super::{MethodError, import_image, import_mesh, to_json};
use crate::artifact::canonical_bytes;
use crate::artifact::jump_maps::{
    ParamMeta, ParamParts, view_field, view_jump_map, view_parameterization, view_walk,
    write_field, write_jump_map, write_parameterization, write_walk,
};
use crate::artifact::kinds::{read_mesh, view_image, write_bundle};
use crate::config::{Config, check_range};
use crate::pipeline::{Dag, Node, NodeError, Stage};
use crate::stages::analyse_exemplar::jump_map::{
    JumpMapParams, build_jump_map, check_exemplar_size,
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
    let mesh = import_mesh(
        &mut dag,
        "import.mesh",
        &config.resolve(&c.inputs.mesh),
        "inputs.mesh",
    )?;
    let exemplar_path = config.resolve(&c.inputs.exemplar);
    let exemplar = import_image(
        &mut dag,
        "import.exemplar",
        &exemplar_path,
        "inputs.exemplar",
    )?;
    let exemplar_file = dag.add_file(&exemplar_path, "inputs.exemplar")?;

    let p = c.analyse_exemplar.clone();
    let jump_map = dag.add(Node {
        name: "analyse_exemplar".into(),
        stage: Stage::AnalyseExemplar,
        algorithm: "jump_map",
        version: JUMP_MAP_VERSION,
        params: canonical_bytes(&p),
        params_json: to_json(&p),
        inputs: vec![exemplar],
        exports: false,
        compute: Box::new(move |ctx| {
            let img = view_image(ctx.artifact(0))?;
            check_exemplar_size(img.width, img.height).map_err(NodeError::input)?;
            let jm = build_jump_map(img, &p, &|f| ctx.progress.set(f));
            Ok(write_jump_map(&jm))
        }),
    });

    let p = c.field.clone();
    let field = dag.add(Node {
        name: "field".into(),
        stage: Stage::Field,
        algorithm: "orientation_field",
        version: FIELD_VERSION,
        params: canonical_bytes(&p),
        params_json: to_json(&p),
        inputs: vec![mesh],
        exports: false,
        compute: Box::new(move |ctx| {
            let mesh = read_mesh(ctx.artifact(0))?;
            let up = orientation_field(&mesh, &p).map_err(NodeError::input)?;
            Ok(write_field(&up))
        }),
    });

    let p = c.parameterize.clone();
    let param = dag.add(Node {
        name: "parameterize".into(),
        stage: Stage::Parameterize,
        algorithm: "jump_offsets",
        version: PARAMETERIZE_VERSION,
        params: canonical_bytes(&p),
        params_json: to_json(&p),
        inputs: vec![mesh, field, exemplar],
        exports: false,
        compute: Box::new(move |ctx| {
            let mesh = read_mesh(ctx.artifact(0))?;
            let up = view_field(ctx.artifact(1))?;
            let img = view_image(ctx.artifact(2))?;
            parameterize(&mesh, up, (img.width, img.height), &p)
        }),
    });

    let p = c.synthesize.clone();
    let walk = dag.add(Node {
        name: "synthesize".into(),
        stage: Stage::Synthesize,
        algorithm: "jump_walk",
        version: WALK_VERSION,
        params: canonical_bytes(&p),
        params_json: to_json(&p),
        inputs: vec![param, jump_map],
        exports: false,
        compute: Box::new(move |ctx| {
            let param = view_parameterization(ctx.artifact(0))?;
            let jm = view_jump_map(ctx.artifact(1))?;
            if param.meta.exemplar != (jm.width, jm.height) {
                return Err(NodeError::internal("parameterization and jump map disagree on the exemplar size"));
            }
            let walk = jump_walk(param.walk_input(), jm, &p, &|f| ctx.progress.set(f));
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
            Ok(write_walk(&walk, (jm.width, jm.height)))
        }),
    });

    let mut maps = Vec::new();
    for (name, path) in &c.inputs.maps {
        let path = config.resolve(path);
        let role = format!("inputs.maps.{name}");
        let img = import_image(&mut dag, &format!("import.map.{name}"), &path, &role)?;
        let file = dag.add_file(&path, &role)?;
        maps.push((name.clone(), path, img, file));
    }

    let p = c.reconstruct.clone();
    let map_names: Vec<(String, String)> = maps
        .iter()
        .map(|(n, path, ..)| (n.clone(), extension_of(path)))
        .collect();
    let exemplar_ext = extension_of(&exemplar_path);
    let mut inputs = vec![mesh, param, walk, exemplar, exemplar_file];
    for (_, _, img, file) in &maps {
        inputs.push(*img);
        inputs.push(*file);
    }
    dag.add(Node {
        name: "reconstruct".into(),
        stage: Stage::Reconstruct,
        algorithm: "jump_blend_export",
        version: RECONSTRUCT_VERSION,
        params: canonical_bytes(&(&p, &map_names, &exemplar_ext)),
        params_json: to_json(&p),
        inputs,
        exports: true,
        compute: Box::new(move |ctx| {
            let mesh = read_mesh(ctx.artifact(0))?;
            let param = view_parameterization(ctx.artifact(1))?;
            let walk = view_walk(ctx.artifact(2))?;
            let exemplar = view_image(ctx.artifact(3))?;
            if walk.addresses.len() != mesh.vertex_count() || param.meta.vertices as usize != mesh.vertex_count() {
                return Err(NodeError::internal("texel addresses and mesh disagree on the vertex count"));
            }
            let sets = corner_sets(&mesh.triangles, &param, walk.addresses).map_err(NodeError::internal)?;
            let single = random_base_set(&sets);
            let mut surfaces = vec![ExportSurface {
                name: "basecolor".into(),
                extension: exemplar_ext.clone(),
                file: &ctx.file(4).bytes,
                shader: BlendShader { sets: &sets, texture: exemplar },
            }];
            for (k, (name, ext)) in map_names.iter().enumerate() {
                let img = view_image(ctx.artifact(5 + 2 * k))?;
                if (img.width, img.height) != (exemplar.width, exemplar.height) {
                    return Err(NodeError::input(format!(
                        "{}: map {name:?} is {}×{}, but the exemplar is {}×{}: maps must be aligned with the exemplar",
                        ctx.file(6 + 2 * k).path.display(),
                        img.width,
                        img.height,
                        exemplar.width,
                        exemplar.height
                    )));
                }
                surfaces.push(ExportSurface {
                    name: name.clone(),
                    extension: ext.clone(),
                    file: &ctx.file(6 + 2 * k).bytes,
                    shader: BlendShader { sets: &sets, texture: img },
                });
            }
            let files = export_textured_mesh(&mesh, &single, (exemplar.width, exemplar.height), &surfaces, &p, &|f| {
                ctx.progress.set(f)
            })
            .map_err(NodeError::input)?;
            let mut files = files;
            // Fig. 3 (right) of the paper: the surface textured with a colour ramp instead of
            // the exemplar shows where patches meet.
            let ramp = colour_ramp(exemplar.width, exemplar.height);
            let opts = crate::render::ViewOptions {
                size: p.preview_size,
                up: glam::Vec3::from(p.up),
                ..Default::default()
            };
            let view = crate::render::render_views(&mesh, &BlendShader { sets: &sets, texture: ramp.view() }, &opts);
            files.push(("patches.png".into(), encode_png(&view, false)));
            Ok(write_bundle(&files))
        }),
    });
    Ok(dag)
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
) -> Result<Vec<u8>, NodeError> {
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
    Ok(write_parameterization(&ParamParts {
        meta: ParamMeta {
            vertices: n as u64,
            scale,
            exemplar: (w, h),
            components: order.seeds.len() as u32,
        },
        order: &order.order,
        seeds: &order.seeds,
        adj_offsets: &adj.offsets,
        neighbors: &adj.neighbors,
        edge_offsets: &offsets,
        boxes: &boxes,
    }))
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
