//! texsyn: texture synthesis on shapes from examples. See README.md and DESIGN.md.

// Numeric code indexes several parallel arrays by one vertex or corner index; iterator
// chains over zips of them read worse than the index loop.
#![allow(clippy::needless_range_loop)]

pub mod artifact;
pub mod cache;
pub mod config;
pub mod methods;
pub mod ops;
pub mod owner;
pub mod pipeline;
pub mod report;
pub mod score;

// The core (meshes, images, solvers, randomness, rasterizer, writers) and the stage algorithms
// are crates of their own (DESIGN.md, Layout); re-exported so `crate::geom::…`,
// `texsyn::stages::…` keep their paths.
pub use texsyn_core::{check, export, geom, graph, image, linalg, memory, random, render};
/// The stage algorithms, one file per algorithm (DESIGN.md, Layout).
pub use texsyn_stages as stages;
