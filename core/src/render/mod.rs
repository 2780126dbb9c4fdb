//! Software rasterizer for previews and texture baking.
//!
//! - [`raster`]: scan conversion of one screen-space triangle (fixed-point edge functions,
//!   top-left fill rule, so triangles sharing an edge leave neither cracks nor double hits).
//! - [`shader`]: what colour a surface has ([`SurfaceShader`]) and the usual implementations.
//! - [`views`]: the three-view preview image ([`render_views`]).
//! - [`atlas`]: a per-triangle texture atlas ([`build_atlas`]) and baking a shader into it
//! - [`chart_atlas`]: charts of faces whose layouts agree, packed into pages ([`build_chart_atlas`]), and baking ([`bake_page`])
//!   ([`bake`]).
//! - [`load`]: the backend of the `render` command ([`render_mesh_file`]).
//!
//! Everything here is deterministic: rows or bands of rows are computed in parallel with rayon,
//! each into its own slots, and no floating-point accumulation depends on the thread count.
//! Transcendental functions go through [`srgb`], written with basic arithmetic only, so the bytes
//! do not depend on the platform's libm either.

pub mod atlas;
pub mod chart_atlas;
pub mod load;
pub mod raster;
pub mod shader;
pub mod srgb;
pub mod up_axis;
pub mod views;

pub use atlas::{ATLAS_GUTTER, Atlas, AtlasError, MAX_ATLAS_SIZE, bake, build_atlas};
pub use chart_atlas::{ChartAtlas, ChartAtlasError, bake_page, build_chart_atlas};
pub use load::{RenderError, render_mesh_file};
pub use shader::{
    ConstantShader, CornerUvShader, MaterialUvShader, SurfaceShader, VertexColorShader,
};
pub use views::{ViewOptions, preview_memory_estimate, render_views, render_views_of_each};
