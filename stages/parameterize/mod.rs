//! Stage: parameterize.
pub mod edge_offsets;
pub mod region_growing;
