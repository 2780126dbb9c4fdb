//! Stage: field.
pub mod orientation_field;
