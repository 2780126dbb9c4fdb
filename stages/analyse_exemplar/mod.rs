//! Stage: analyse_exemplar.
pub mod appearance_space;
pub mod candidate_triples;
pub mod feature_mask;
pub mod gaussian_stack;
pub mod jump_map;
pub mod texel_variants;
pub mod texture_feature_lines;
