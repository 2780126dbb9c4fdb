//! Where the repository's test data is, and loading its exemplar images. Shared by the
//! integration tests (through `common`) and bench/'s examples (`#[path]`).
#![allow(dead_code)] // each user takes a different part

use std::path::PathBuf;
use texsyn::image::{Image, decode_image};

/// The repository's root: the first folder at or above the compiling crate's (the root
/// crate for the tests, `bench/` for the examples) that holds `tests/data`.
pub fn repo() -> PathBuf {
    let here = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    here.ancestors()
        .find(|d| d.join("tests/data").is_dir())
        .map(PathBuf::from)
        .unwrap_or(here)
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
