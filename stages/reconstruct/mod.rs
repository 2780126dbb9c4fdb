//! Stage: reconstruct: what users open (textured meshes, baked textures, images, previews).
pub mod blend2d;
pub mod displacement;
pub mod feature_aligned_export;
pub mod feature_aligned_report;
pub mod finest_level_bake;
pub mod jump_blend;
pub mod jump_export;
pub mod patch_lookup;
pub mod relief_export;
pub mod solid_colour;
pub mod textured_export;
pub mod vertex_colour_export;
pub mod wide_blend;
