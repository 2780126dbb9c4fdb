//! Stage: analyse_exemplar.
pub mod jump_map;
pub mod texel_variants;
