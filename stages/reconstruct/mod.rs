//! Stage: reconstruct.
pub mod jump_blend;
pub mod textured_export;
