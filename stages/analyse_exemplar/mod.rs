//! Stage: analyse_exemplar.
