//! `texsyn gc`: trims the cache to a size, least recently used objects first.

use super::Globals;
use anyhow::Result;
use texsyn::cache::{Cache, parse_size};

#[derive(clap::Args)]
pub struct GcArgs {
    /// Budget, e.g. 500M or 2G.
    #[arg(long)]
    max_size: String,
}

/// `texsyn gc`.
pub fn gc(args: &GcArgs, g: &Globals) -> Result<i32> {
    let budget = parse_size(&args.max_size)?;
    // A mistyped --cache is an error, not a new empty cache; an object that cannot be
    // removed is an error naming it.
    let cache = Cache::open_existing(&g.cache_dir)?;
    let report = cache.gc(budget)?;
    if !g.quiet {
        println!(
            "removed {} objects ({}), {} kept in {}",
            report.removed,
            texsyn::memory::human(report.removed_bytes),
            texsyn::memory::human(report.kept_bytes),
            cache.root().display()
        );
    }
    Ok(0)
}
