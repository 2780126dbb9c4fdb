//! texsyn's core: meshes, images, graphs (compressed lists, shortest paths), solvers,
//! bit-reproducible f32 kernels, max-flow, counter-based randomness, the software rasterizer
//! and the mesh/image writers (DESIGN.md, Layout). It sits below everything: it knows nothing
//! of stages, the pipeline, the cache, artifact formats, configs or methods.

// Numeric code indexes several parallel arrays by one vertex or corner index; iterator
// chains over zips of them read worse than the index loop.
#![allow(clippy::needless_range_loop)]

pub mod algorithm;
pub mod check;
pub mod export;
pub mod geom;
pub mod graph;
pub mod image;
pub mod linalg;
pub mod math;
pub mod max_flow;
pub mod memory;
pub mod random;
pub mod render;
pub mod simd;
