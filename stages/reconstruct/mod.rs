//! Stage: reconstruct.
