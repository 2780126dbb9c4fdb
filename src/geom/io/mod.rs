//! Mesh readers and writers. (Being written: see the helper brief.)
use super::Mesh;
use std::path::{Path, PathBuf};

/// A mesh file that could not be read. Every message names the file, where in it the problem
/// is (line for text formats, element index or byte offset for binary ones), and what was wrong.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("{path}: {location}: {message}")]
    Parse { path: PathBuf, location: String, message: String },
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
    #[error("{path}: unsupported mesh format (expected .obj, .off, .ply or .stl)")]
    UnsupportedFormat { path: PathBuf },
}

/// Reads a mesh, choosing the reader by the file's extension.
pub fn read_mesh(path: &Path) -> Result<Mesh, MeshError> {
    let _ = path;
    unimplemented!()
}
