//! Stage algorithms, grouped by pipeline stage. Each file implements one algorithm of one paper.
//!
//! This crate depends on the core only (DESIGN.md, Layout): it cannot reach the pipeline, the
//! cache, the artifact formats, configs or methods.

// Numeric code indexes several parallel arrays by one vertex or corner index; iterator
// chains over zips of them read worse than the index loop.
#![allow(clippy::needless_range_loop)]

// The core's modules under their usual names, so `crate::geom::…` reads as in the core.
use texsyn_core::{check, export, geom, graph, image, linalg, random, render, simd};

pub mod analyse_exemplar;
pub mod extract;
pub mod field;
pub mod parameterize;
pub mod reconstruct;
pub mod synthesize;

#[cfg(test)]
mod testing;
