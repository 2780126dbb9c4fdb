//! Methods: each expands its config section into a DAG of pipeline nodes (DESIGN.md, "A run").

pub mod geometry_images;
pub mod jump_maps;
pub mod solid;
pub mod synth2d;

use crate::artifact::kinds::{write_image, write_mesh};
use crate::config::{Config, ConfigError};
use crate::pipeline::{Dag, InputRef, Node, NodeError, Stage};
use std::path::{Path, PathBuf};

/// The methods a config may name.
pub const METHODS: &[&str] = &["jump_maps", "synth2d", "geometry_images", "solid"];

#[derive(Debug, thiserror::Error)]
pub enum MethodError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error("{0}")]
    Input(#[from] std::io::Error),
    #[error("{path}: method {method:?} is not implemented (known: {known})")]
    UnknownMethod {
        path: PathBuf,
        method: String,
        known: String,
    },
}

/// A config turned into work: the DAG and the nodes whose bundles are the run's outputs.
pub struct Plan {
    pub dag: Dag,
    /// Default output directory (`out/<config stem>`), used unless `--out` is given.
    pub default_out: PathBuf,
}

pub fn plan(config: &Config) -> Result<Plan, MethodError> {
    let method = config.method()?;
    let dag = match method {
        "jump_maps" => jump_maps::build(config)?,
        "synth2d" => synth2d::build(config)?,
        "geometry_images" => geometry_images::build(config)?,
        "solid" => solid::build(config)?,
        other => {
            return Err(MethodError::UnknownMethod {
                path: config.path.clone(),
                method: other.to_owned(),
                known: METHODS.join(", "),
            });
        }
    };
    Ok(Plan {
        dag,
        default_out: Path::new("out").join(&config.stem),
    })
}

/// Code versions of the import nodes: bump when a reader's output for the same bytes changes.
const IMPORT_MESH_VERSION: u32 = 1;
const IMPORT_IMAGE_VERSION: u32 = 1;

fn extension(path: &Path) -> String {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}

/// Adds the node that parses and validates a mesh file.
pub(crate) fn import_mesh(
    dag: &mut Dag,
    name: &str,
    path: &Path,
    role: &str,
) -> Result<InputRef, MethodError> {
    let file = dag.add_file(path, role)?;
    // The format is part of the key: the same bytes read as another format mean something else.
    let format = extension(path);
    Ok(dag.add(Node {
        name: name.to_owned(),
        stage: Stage::Import,
        algorithm: "mesh_reader",
        version: IMPORT_MESH_VERSION,
        params: crate::artifact::canonical_bytes(&format),
        params_json: serde_json::json!({ "format": format }),
        inputs: vec![file],
        exports: false,
        compute: Box::new(move |ctx| {
            let f = ctx.file(0);
            let mesh =
                crate::geom::io::read_mesh_bytes(&f.path, &f.bytes).map_err(NodeError::input)?;
            Ok(write_mesh(&mesh))
        }),
    }))
}

/// Adds the node that decodes an image file (PNG, JPEG, EXR).
pub(crate) fn import_image(
    dag: &mut Dag,
    name: &str,
    path: &Path,
    role: &str,
) -> Result<InputRef, MethodError> {
    let file = dag.add_file(path, role)?;
    let format = extension(path);
    Ok(dag.add(Node {
        name: name.to_owned(),
        stage: Stage::Import,
        algorithm: "image_reader",
        version: IMPORT_IMAGE_VERSION,
        params: crate::artifact::canonical_bytes(&format),
        params_json: serde_json::json!({ "format": format }),
        inputs: vec![file],
        exports: false,
        compute: Box::new(move |ctx| {
            let f = ctx.file(0);
            let img = crate::image::decode_image(&f.path, &f.bytes).map_err(NodeError::input)?;
            Ok(write_image(&img))
        }),
    }))
}

/// The JSON form of a parameter struct (for `graph`, `status`, `--json`).
pub(crate) fn to_json<T: serde::Serialize>(v: &T) -> serde_json::Value {
    serde_json::to_value(v).unwrap_or(serde_json::Value::Null)
}
