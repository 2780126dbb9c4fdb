//! Stage: synthesize.
pub mod jump_walk;
