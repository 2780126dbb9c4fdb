//! Stage: synthesize.
