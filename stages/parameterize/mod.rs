//! Stage: parameterize.
pub mod edge_offsets;
pub mod edge_refinement;
pub mod geometry_image;
pub mod jump_parameterization;
pub mod region_growing;
pub mod sqrt2_subdivision;
pub mod volume_embedding;
