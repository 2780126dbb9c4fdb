//! Stage: synthesize: the methods' synthesis proper.
pub mod dependent_set;
pub mod geometry_texture;
pub mod history_window;
pub mod jump_walk;
pub mod solid_synthesis;
pub mod synth2d;
