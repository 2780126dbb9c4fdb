//! Stage: field.
pub mod orientation_field;
pub mod param_field;
pub mod quaternion_field;
pub mod sweep_field;
