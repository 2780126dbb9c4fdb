//! texsyn: texture synthesis on shapes from examples. See README.md and DESIGN.md.

// Numeric code indexes several parallel arrays by one vertex or corner index; iterator
// chains over zips of them read worse than the index loop.
#![allow(clippy::needless_range_loop)]

pub mod artifact;
pub mod bench;
pub mod cache;
pub mod check;
pub mod config;
pub mod export;
pub mod geom;
pub mod image;
pub mod linalg;
pub mod methods;
pub mod pipeline;
pub mod random;
pub mod render;

/// The stage algorithms, one file per algorithm (DESIGN.md, Layout).
#[path = "../stages/mod.rs"]
pub mod stages;
