//! Operations on whole runs, above the pipeline and the methods: lock files, packed runs,
//! parameter sweeps and the Slurm executor they can run on. Nothing below this floor imports
//! it.

pub mod lockfile;
pub mod pack;
pub mod slurm;
pub mod sweep;
