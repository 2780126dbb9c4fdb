//! Sketch-guided solid synthesis (Zhang, Du, Lai, Ni & Hu, "Sketch guided solid texturing",
//! §4–5): the on-demand, brick-by-brick synthesis ([`solid_synthesis`]) and the two pieces of
//! §5 it rests on, the history windows of grid and dual-grid correction ([`history_window`])
//! and the dependent set of a request worked out backwards through them ([`dependent_set`]).

/// The `solid_bricks` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("solid_bricks", 2);

pub mod dependent_set;
pub mod field_integration;
pub mod history_window;
pub mod solid_synthesis;
