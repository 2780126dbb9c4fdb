//! Stage: extract: texture or features taken out of a shape.
pub mod bilateral_difference;
pub mod height_field;
pub mod planar_ransac;
pub mod sample_region;
