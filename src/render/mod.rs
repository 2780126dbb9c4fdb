//! Software rasterizer for previews and texture baking.
pub mod shader;
