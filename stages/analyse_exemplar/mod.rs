//! Stage: analyse_exemplar.
pub mod jump_map;
