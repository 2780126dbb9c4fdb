//! Import nodes: an input file parsed and validated into an artifact, keyed by its bytes and
//! its format.

use super::MethodError;
use crate::artifact::Format;
use crate::config::Config;
use crate::pipeline::{Dag, Handle, NodeError, NodeSpec, Stage};
use std::path::{Path, PathBuf};

/// A format that an input file is read into by an `import` node.
pub trait Import: Format + Sized {
    /// The reader's name (the node's algorithm, part of its key).
    const READER: &'static str;
    /// Bump when the reader's output for the same bytes changes.
    const VERSION: u32;
    fn read(path: &Path, bytes: &[u8]) -> Result<Self, Box<dyn std::error::Error + Send + Sync>>;
}

impl Import for crate::geom::Mesh {
    const READER: &'static str = "mesh_reader";
    const VERSION: u32 = 1;
    fn read(path: &Path, bytes: &[u8]) -> Result<Self, Box<dyn std::error::Error + Send + Sync>> {
        let mesh = crate::geom::io::read_mesh_bytes(path, bytes)?;
        // Past this, edge lengths and areas overflow f32 and every method's numbers turn to
        // infinities and zeros; no real model needs it (a light-year in millimetres is 1e19).
        const MAX_COORDINATE: f32 = 1e15;
        if let Some((v, p)) = mesh
            .positions
            .iter()
            .enumerate()
            .find(|(_, p)| p.abs().max_element() > MAX_COORDINATE)
        {
            return Err(format!(
                "{}: vertex {v} is at {p}: coordinates beyond ±{MAX_COORDINATE:e} overflow the geometry; scale the mesh down",
                path.display()
            )
            .into());
        }
        Ok(mesh)
    }
}

impl Import for crate::image::Image {
    const READER: &'static str = "image_reader";
    const VERSION: u32 = 1;
    fn read(path: &Path, bytes: &[u8]) -> Result<Self, Box<dyn std::error::Error + Send + Sync>> {
        Ok(crate::image::decode_image(path, bytes)?)
    }
}

/// The import node's parameters: the file's format, taken from its extension. It is part of
/// the key because the same bytes read as another format mean something else.
#[derive(serde::Serialize)]
struct ImportParams {
    format: String,
}

pub(crate) fn extension(path: &Path) -> String {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}

/// Adds the node that parses and validates an input file. `role` is the config key that
/// named it, for errors.
pub fn import<F: Import>(
    dag: &mut Dag,
    name: &str,
    path: &Path,
    role: &str,
) -> Result<Handle<F>, MethodError> {
    let file = dag.file(path, role)?;
    let params = ImportParams {
        format: extension(path),
    };
    Ok(dag.node(
        NodeSpec::new(Stage::Import, F::READER, F::VERSION).named(name),
        params,
        file,
        |_, _, f| F::read(&f.path, &f.bytes).map_err(NodeError::Input),
    ))
}

/// Imports `inputs.<key>`, a path `config` gives, as the node `import.<key>`.
pub(crate) fn input<F: Import>(
    dag: &mut Dag,
    config: &Config,
    key: &str,
    path: &Path,
) -> Result<Handle<F>, MethodError> {
    let role = format!("inputs.{key}");
    import(dag, &format!("import.{key}"), &config.resolve(path), &role)
}

/// Input files of one kind that several nodes use: each path is imported once, the first as
/// `name`, the next ones as `name.1`, `name.2`, … (in the order they are first asked for).
pub(crate) struct Imports<F> {
    name: &'static str,
    done: Vec<(PathBuf, Handle<F>)>,
}

impl<F: Import> Imports<F> {
    pub(crate) fn new(name: &'static str) -> Self {
        Imports {
            name,
            done: Vec::new(),
        }
    }

    /// The import of `path`; `role` is the config key that names it, for errors.
    pub(crate) fn get(
        &mut self,
        dag: &mut Dag,
        path: &Path,
        role: &str,
    ) -> Result<Handle<F>, MethodError> {
        if let Some((_, h)) = self.done.iter().find(|(p, _)| p == path) {
            return Ok(*h);
        }
        let name = match self.done.len() {
            0 => self.name.to_string(),
            n => format!("{}.{n}", self.name),
        };
        let h = import::<F>(dag, &name, path, role)?;
        self.done.push((path.to_owned(), h));
        Ok(h)
    }
}
