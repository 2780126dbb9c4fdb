//! Software rasterizer for previews and texture baking.
