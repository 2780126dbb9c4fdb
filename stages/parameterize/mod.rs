//! Stage: parameterize.
