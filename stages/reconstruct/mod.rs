//! Stage: reconstruct.
pub mod jump_blend;
