//! Stage algorithms, grouped by pipeline stage. Each file implements one algorithm of one paper.
pub mod analyse_exemplar;
pub mod extract;
pub mod field;
pub mod parameterize;
pub mod reconstruct;
pub mod synthesize;
