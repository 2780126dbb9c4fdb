//! Stage: synthesize: the methods' synthesis proper.
pub mod geometry_texture;
pub mod graph_matching;
pub mod jump_walk;
pub mod occurrence;
pub mod solid;
pub mod surface_metric;
pub mod synth2d;
pub mod texture_optimization;
