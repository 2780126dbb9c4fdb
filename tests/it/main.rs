//! The integration tests, in one binary so that `cargo test` links one executable, not one per
//! file. Each module is one area; `common` holds what they share.
//!
//! Two tiers (README, "Tests"): the default tier runs on every `cargo test --release`; tests
//! of the full tier (full-size locks, memory calibration, Slurm, the glTF validator, fault
//! injection, 8 threads) run only with `TEXSYN_TEST_TIER=full`, which `.ci/run` sets, and
//! say on stderr that they were skipped otherwise.

mod common;

mod bad_meshes;
mod cache_integrity;
mod chart_atlas;
mod cli;
mod extract;
mod fault_injection;
mod feature_aligned;
mod geometry_image;
mod geometry_images_pipeline;
mod geometry_texture;
mod gi_long_parts;
mod gi_sheet_quality;
mod graph_matching;
mod jump_map;
mod key_locks;
mod locks;
mod memory_budget;
mod mesh_io;
mod mesh_io_roundtrip;
mod output_integrity;
mod pack;
mod pipeline;
mod reader_properties;
mod registry;
mod render_export;
mod report;
mod score;
mod slurm;
mod solid_pipeline;
mod solid_shards;
mod solid_switches;
mod solid_synthesis;
mod sweep;
mod sweep_slurm;
mod typed_wiring;
mod watch;
