//! Sketch-guided solid synthesis (Zhang, Du, Lai, Ni & Hu, "Sketch guided solid texturing",
//! §4–5): the on-demand, brick-by-brick synthesis ([`solid_synthesis`]) and the two pieces of
//! §5 it rests on, the history windows of grid and dual-grid correction ([`history_window`])
//! and the dependent set of a request worked out backwards through them ([`dependent_set`]).

/// The `solid_bricks` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("solid_bricks", 3);

/// Estimated peak memory, in bytes, of a solid of `resolution` voxels on its longest side
/// asked for `request`. The volume's voxel masks and their prefix sums are dense over the
/// volume's box (at most `resolution³` voxels). A box request keeps its finest bricks (12
/// bytes a voxel) and needs about 16 bytes per voxel of that cube bound and 180 MB besides
/// (the exemplar analysis); a section needs about two bytes per voxel and 48 MB (its
/// dependent sets are kept in chunks with no per-voxel lists; the process's peak resident
/// memory, VmHWM, measured on solid_trivial: 56 MiB at 128, 75 MiB at 256, 158 MiB at 384).
/// Measured (solid_trivial, elephant): surface 119 MB at 128, 272 MB at 256, 523 MB at 384.
/// The elephant's box fills about half its cube, so the cube bound stays within 2× for slim
/// and cubic shapes alike.
///
/// A surface request synthesizes each level in batches whose working set is bounded
/// (`BatchLimits` in `solid_synthesis/plan.rs`: about 1.2 GiB with the resident bricks of two
/// levels) and keeps only the surface's bricks: the same 16 bytes per voxel while that is
/// smaller, never more than the batch bound, plus half a byte per voxel for the volume's
/// masks (measured on the cow: 529 MB at 512; BENCHMARKS.md has 1024).
pub fn memory_estimate(
    request: &crate::parameterize::volume_embedding::Request,
    resolution: u64,
) -> u64 {
    use crate::parameterize::volume_embedding::Request;
    let r = resolution;
    match request {
        Request::Section { .. } => 2 * r * r * r + (48 << 20),
        Request::Box { .. } => 16 * r * r * r + (180 << 20),
        Request::Surface => (16 * r * r * r).min(1_200 << 20) + r * r * r / 2 + (180 << 20),
    }
}

pub mod dependent_set;
pub mod field_integration;
pub mod history_window;
pub mod solid_synthesis;
