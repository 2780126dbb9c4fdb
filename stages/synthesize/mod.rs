//! Stage: synthesize.
pub mod synth2d;
