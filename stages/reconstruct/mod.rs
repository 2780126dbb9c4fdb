//! Stage: reconstruct.
pub mod blend2d;
