//! Exports: OBJ + MTL ([`obj`]), binary glTF ([`glb`]), EXR ([`exr`]) and PNG ([`png`]).
//!
//! Writers return bytes or strings and never touch the file system, so the pipeline can hash
//! and store what they produce. Output is deterministic: fixed formatting, fixed key order.

pub mod decimal;
pub mod exr;
pub mod glb;
pub mod obj;
pub mod png;

pub use glb::{GlbAttribute, GlbMaterial, GlbMesh, write_glb};
pub use obj::{MtlMaps, write_mtl, write_obj};
pub use png::encode_png;
