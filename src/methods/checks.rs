//! Checks made when a method plans, before any node runs: parameters that must fit an input
//! (read from its header) or the memory budget, and required keys.

use super::MethodError;
use crate::config::Config;
use std::path::{Path, PathBuf};

/// The size of the exemplar `path` (as the config gives it) and its resolved path, read from
/// the image header so parameters that must fit it are refused before any node runs. `None`
/// when the header cannot be read: the import node then names the problem.
pub(crate) fn exemplar_size(config: &Config, path: &Path) -> Option<((u32, u32), PathBuf)> {
    let path = config.resolve(path);
    let reader = image::ImageReader::open(&path)
        .ok()?
        .with_guessed_format()
        .ok()?;
    Some((reader.into_dimensions().ok()?, path))
}

/// Resolves `parameterize.scale = "auto"` (read as 0, also when not given) from the mesh's
/// bounding box and the exemplar's width ([`automatic_scale`]), before any node is keyed, so
/// a key holds the number used and a given number keys as before. When the mesh or the
/// exemplar cannot be read, the scale is left at 0: their import nodes fail first and name
/// the problem. Returns the mesh when the scale was resolved from it, so a method can fit
/// the scale to its own budget too.
///
/// [`automatic_scale`]: crate::stages::parameterize::automatic_scale
pub(crate) fn resolve_scale(
    config: &Config,
    scale: &mut f32,
    mesh: &Path,
    exemplar: &Path,
) -> Option<AutoMesh> {
    if *scale > 0.0 {
        return None;
    }
    let ((width, _), _) = exemplar_size(config, exemplar)?;
    let path = config.resolve(mesh);
    let bytes = texsyn_core::geom::io::read_regular_file(&path).ok()?;
    let mesh = crate::geom::io::read_mesh_bytes(&path, &bytes).ok()?;
    *scale = crate::stages::parameterize::automatic_scale(&mesh, width);
    tracing::info!(
        "parameterize.scale = \"auto\": {:.4} exemplar texels per unit (the exemplar's {width} texels span a quarter of {}'s bounding-box diagonal)",
        *scale,
        path.display()
    );
    // What the mesh is read from: its bytes and the format its name gives, by this reader.
    use super::import::Import;
    let mut h = blake3::Hasher::new();
    h.update(<crate::geom::Mesh as Import>::READER.as_bytes());
    h.update(&<crate::geom::Mesh as Import>::VERSION.to_le_bytes());
    h.update(path.extension().unwrap_or_default().as_encoded_bytes());
    h.update(b"\0");
    h.update(&bytes);
    Some(AutoMesh {
        mesh,
        source: crate::artifact::ContentHash(*h.finalize().as_bytes()),
    })
}

/// The mesh an automatic scale was resolved from, with what it was read from.
pub(crate) struct AutoMesh {
    pub mesh: crate::geom::Mesh,
    /// A hash of the file's bytes and its format: the mesh is a function of these.
    pub source: crate::artifact::ContentHash,
}

/// Refuses, before any work, a parameter whose estimated memory is over the budget
/// (`--max-memory`), naming a value that fits. `estimate` gives bytes for a value; it must
/// grow with the value.
pub(crate) fn check_memory(
    config: &Config,
    key: &str,
    value: u64,
    estimate: impl Fn(u64) -> u64,
    show: impl Fn(u64) -> String,
) -> Result<(), MethodError> {
    crate::memory::check_budget(key, value, estimate, show)
        .map_err(|e| MethodError::Config(config.invalid(key, &e.to_string())))
}

/// The preview of `reconstruct.preview_size` pixels per view
/// ([`crate::render::preview_memory_estimate`]).
pub(crate) fn check_preview_memory(config: &Config, size: u32) -> Result<(), MethodError> {
    check_memory(
        config,
        "reconstruct.preview_size",
        size as u64,
        crate::render::preview_memory_estimate,
        |s| s.to_string(),
    )
}

/// The texel variants of a geometry-image sample of `extract.size`² texels
/// ([`TexelVariantParams::memory_estimate`]).
///
/// [`TexelVariantParams::memory_estimate`]: crate::stages::analyse_exemplar::texel_variants::TexelVariantParams::memory_estimate
pub(crate) fn check_variant_memory(
    config: &Config,
    size: u32,
    p: &crate::stages::analyse_exemplar::texel_variants::TexelVariantParams,
    per_texel: bool,
) -> Result<(), MethodError> {
    check_memory(
        config,
        "extract.size",
        size as u64,
        |s| p.memory_estimate(s, per_texel),
        |s| s.to_string(),
    )
}

/// A solid of `parameterize.resolution` voxels on its longest side
/// ([`crate::stages::synthesize::solid::memory_estimate`]).
pub(crate) fn check_solid_memory(
    config: &Config,
    resolution: u32,
    request: &crate::stages::parameterize::volume_embedding::Request,
) -> Result<(), MethodError> {
    check_memory(
        config,
        "parameterize.resolution",
        resolution as u64,
        |r| crate::stages::synthesize::solid::memory_estimate(request, r),
        |r| r.to_string(),
    )
}

/// The baked atlas of `reconstruct.atlas_size` texels per side
/// ([`crate::stages::reconstruct::textured_export::atlas_memory_estimate`]).
pub(crate) fn check_atlas_memory(config: &Config, side: u32) -> Result<(), MethodError> {
    check_memory(
        config,
        "reconstruct.atlas_size",
        side as u64,
        crate::stages::reconstruct::textured_export::atlas_memory_estimate,
        |a| a.to_string(),
    )
}
