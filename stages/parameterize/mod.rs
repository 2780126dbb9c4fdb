//! Stage: parameterize.
pub mod edge_offsets;
pub mod edge_refinement;
pub mod geometry_image;
pub mod jump_parameterization;
pub mod region_growing;
pub mod scale_keys;
pub mod sqrt2_subdivision;
pub mod volume_embedding;

/// Reads `parameterize.scale`: a positive number of exemplar texels per object unit, or
/// `"auto"`, read as 0, which the method resolves from the mesh and the exemplar before any
/// node is keyed ([`automatic_scale`]).
pub fn texels_or_auto<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f32, D::Error> {
    use serde::Deserialize;
    use serde::de::Error;
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum Given {
        Texels(f64),
        Word(String),
    }
    match Given::deserialize(d)? {
        Given::Texels(s) if s.is_finite() && s > 0.0 && s <= f32::MAX as f64 => Ok(s as f32),
        Given::Word(w) if w == "auto" => Ok(0.0),
        Given::Texels(s) => Err(D::Error::custom(format!(
            "must be a positive number of texels per unit or \"auto\", got {s}"
        ))),
        Given::Word(w) => Err(D::Error::custom(format!(
            "must be a positive number of texels per unit or \"auto\", got {w:?}"
        ))),
    }
}

/// The scale `"auto"` picks, jump maps' rule: the exemplar's `width` spans a quarter of the
/// mesh's bounding-box diagonal, whatever the mesh's units (1 for a degenerate mesh).
pub fn automatic_scale(mesh: &texsyn_core::geom::Mesh, width: u32) -> f32 {
    let (lo, hi) = mesh.bounds();
    let diag = (hi - lo).length();
    if diag > 0.0 && diag.is_finite() {
        width as f32 / (0.25 * diag)
    } else {
        1.0
    }
}
