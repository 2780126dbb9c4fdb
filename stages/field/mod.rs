//! Stage: field.
pub mod coarse_field_smoothing;
pub mod curve_grouping;
pub mod feature_field;
pub mod orientation_field;
pub mod param_field;
pub mod quaternion_field;
pub mod sweep_field;
