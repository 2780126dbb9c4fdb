//! Stage: field.
