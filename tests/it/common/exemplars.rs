//! Where the repository's test data is, and loading its exemplar images. Shared by the
//! integration tests (through `common`) and the examples (`#[path]`).
#![allow(dead_code)] // each user takes a different part

use std::path::PathBuf;
use texsyn::image::{Image, decode_image};

pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The path of an exemplar image in `tests/data/exemplars` (or `name` itself if absolute).
pub fn exemplar_path(name: &str) -> PathBuf {
    repo().join("tests/data/exemplars").join(name)
}

/// An exemplar image of `tests/data/exemplars`, decoded.
pub fn load_exemplar(name: &str) -> Image {
    let path = exemplar_path(name);
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    decode_image(&path, &bytes).unwrap()
}
