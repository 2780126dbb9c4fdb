//! Stage: synthesize: the methods' synthesis proper.
pub mod jump_walk;
pub mod synth2d;
