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

use super::{Method, MethodError, Planned, import};
use crate::artifact::Bundle;
use crate::artifact::jump_maps::{OrientationField, TexelAddresses};
use crate::config::Config;
use crate::geom::Mesh;
use crate::image::{Image, ImageView};
use crate::pipeline::{Dag, FileInput, Handle, NodeError, NodeSpec, Stage};
use crate::score::charts::JumpMapNodes;
use crate::score::{Item, Run, ScoreFailure};
use crate::stages::analyse_exemplar::jump_map::{
    JumpMap, JumpMapParams, build_jump_map, check_exemplar_size,
};
use crate::stages::field::orientation_field::{FieldParams, orientation_field};
use crate::stages::parameterize::jump_parameterization::{
    ParameterizeError, ParameterizeParams, jump_parameterization,
};
use crate::stages::reconstruct::jump_export::{AlignedMap, JumpExportError, export_jump_textured};
use crate::stages::reconstruct::textured_export::ExportParams;
use crate::stages::synthesize::jump_walk::{WalkParams, jump_walk};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::PathBuf;

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

/// The export's own file names a map's name must not produce: a map `N` exports `N.EXT` and
/// `baked_N.png` (or `baked_N_K.png`, one per page), beside `texture.EXT` (the exemplar),
/// `baked_basecolor*.png`, `textured.*`, `baked.*`, `preview.png` and `patches.png`.
const RESERVED_MAP_NAMES: [&str; 6] = [
    "basecolor",
    "texture",
    "textured",
    "baked",
    "preview",
    "patches",
];

/// Why the map name `name` could export a file of the same name as another export file (a
/// reserved name, a `baked_` prefix, or `M_K` beside a map `M`, whose pages are
/// `baked_M_K.png`); `None` when every name it produces is its own.
fn map_name_clash<'a>(name: &str, all: impl Iterator<Item = &'a String>) -> Option<String> {
    if RESERVED_MAP_NAMES.contains(&name) {
        return Some(format!(
            "the name {name:?} is the export's own (reserved: {}); choose another",
            RESERVED_MAP_NAMES.join(", ")
        ));
    }
    if name.starts_with("baked_") {
        return Some("names starting with `baked_` are the baked pages'; choose another".into());
    }
    for other in all {
        if let Some(k) = name
            .strip_prefix(other.as_str())
            .and_then(|r| r.strip_prefix('_'))
            && !k.is_empty()
            && k.bytes().all(|b| b.is_ascii_digit())
        {
            return Some(format!(
                "map {other:?}'s baked pages are named baked_{other}_K.png, so {name:?} \
                 could export the same file name; choose another"
            ));
        }
    }
    None
}

/// The `jump_maps` method.
pub struct JumpMaps;

impl Method for JumpMaps {
    fn name(&self) -> &'static str {
        "jump_maps"
    }

    fn plan(&self, config: &Config) -> Result<(Dag, Box<dyn Planned>), MethodError> {
        let (dag, nodes) = build(config)?;
        Ok((dag, Box::new(nodes)))
    }
}

impl Planned for JumpMapNodes {
    fn score(&self, run: &Run<'_>, _: &mut Vec<String>) -> Result<Vec<Item>, ScoreFailure> {
        crate::score::charts::jump_maps(run, self)
    }
}

fn build(config: &Config) -> Result<(Dag, JumpMapNodes), MethodError> {
    let c: JumpMapsConfig = config.parse()?;
    config.check("analyse_exemplar", c.analyse_exemplar.validate())?;
    config.check("field", c.field.validate())?;
    config.check("parameterize", c.parameterize.validate())?;
    config.check("synthesize", c.synthesize.validate())?;
    config.check("reconstruct", c.reconstruct.validate())?;
    // No up-front memory check on `reconstruct.atlas_size`: it caps a page's side, and pages
    // are only as big as the charts they hold (the need follows the surface's area in texels).
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
        if let Some(why) = map_name_clash(name, c.inputs.maps.keys()) {
            return Err(config.invalid(&format!("inputs.maps.{name}"), &why).into());
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
        NodeSpec::of(Stage::Field, crate::stages::field::orientation_field::NODE),
        c.field.clone(),
        mesh,
        |_, p, mesh| {
            if let Some(w) = crate::geom::mesh_check::mesh_health(&mesh).warning("jump_maps") {
                tracing::warn!("{w}");
            }
            Ok(OrientationField(
                orientation_field(&mesh, p).map_err(NodeError::input)?,
            ))
        },
    );

    let param = dag.node(
        NodeSpec::of(
            Stage::Parameterize,
            crate::stages::parameterize::jump_parameterization::NODE,
        ),
        c.parameterize.clone(),
        (mesh, field, exemplar),
        |_, p, (mesh, up, img)| {
            jump_parameterization(&mesh, up, (img.width, img.height), p)
                .map_err(|e| NodeError::classify(e, ParameterizeError::is_internal))
        },
    );

    let walk = dag.node(
        NodeSpec::of(Stage::Synthesize, crate::stages::synthesize::jump_walk::NODE),
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
        NodeSpec::of(
            Stage::Reconstruct,
            crate::stages::reconstruct::jump_export::NODE,
        ),
        params,
        (mesh, param, walk, exemplar, exemplar_file, maps),
        |ctx, p, (mesh, param, walk, exemplar, exemplar_file, maps)| {
            let basecolor = ("basecolor".to_owned(), p.exemplar_format.clone());
            let maps: Vec<AlignedMap> = p
                .maps
                .iter()
                .zip(maps)
                .map(|(m, (img, file))| aligned(m, img, file))
                .collect();
            let files = export_jump_textured(
                &mesh,
                &param,
                walk.addresses,
                &aligned(&basecolor, exemplar, exemplar_file),
                &maps,
                &p.export,
                &|f| ctx.progress.set(f),
            );
            let files = files.map_err(|e| NodeError::classify(e, JumpExportError::is_internal))?;
            let mut names: Vec<&str> = files.iter().map(|(n, _)| n.as_str()).collect();
            names.sort_unstable();
            if let Some(w) = names.windows(2).find(|w| w[0] == w[1]) {
                return Err(NodeError::input(format!(
                    "two exported files would be named {:?}: rename the map in inputs.maps \
                     whose file names collide",
                    w[0]
                )));
            }
            Ok(Bundle::from(files))
        },
    );
    let nodes = JumpMapNodes {
        mesh,
        parameterize: param,
        synthesize: walk,
        exemplar,
    };
    Ok((dag, nodes))
}

/// The jump map of an exemplar (analyse-exemplar, §2 of the 2002 paper); `synth2d` uses the
/// same node, so the two methods share the cached map.
pub(crate) fn add_jump_map(
    dag: &mut Dag,
    exemplar: Handle<Image>,
    params: JumpMapParams,
) -> Handle<JumpMap> {
    dag.node(
        NodeSpec::of(
            Stage::AnalyseExemplar,
            crate::stages::analyse_exemplar::jump_map::NODE,
        ),
        params,
        exemplar,
        |ctx, p, img| {
            check_exemplar_size(img.width, img.height).map_err(NodeError::input)?;
            Ok(build_jump_map(img, p, &|f| ctx.progress.set(f)))
        },
    )
}

/// An image and the file it came from, textured under `name` in format `format`.
fn aligned<'a>(
    (name, format): &(String, String),
    image: ImageView<'a>,
    file: &'a FileInput,
) -> AlignedMap<'a> {
    AlignedMap {
        name: name.clone(),
        format: format.clone(),
        image,
        path: file.path.clone(),
        bytes: &file.bytes,
    }
}

/// What the reconstruct node's key holds: the export parameters, each extra map's name and
/// file format, and the exemplar's format (the files are copied into the export as they are).
#[derive(Serialize)]
struct ReconstructParams {
    export: ExportParams,
    maps: Vec<(String, String)>,
    exemplar_format: String,
}

/// A map's file format for the export: its extension, or PNG for a file without one.
fn extension_of(p: &std::path::Path) -> String {
    match super::extension(p) {
        e if e.is_empty() => "png".into(),
        e => e,
    }
}
