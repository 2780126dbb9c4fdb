//! `texsyn pack` and `texsyn unpack`: a run in one archive (the config, its input files, the
//! lock, every node's cached artifact and the outputs, in a zstd-compressed tar), and its
//! import into a cache after every entry is checked, with `-o` also the config, inputs, lock
//! and outputs written out.

use super::{Globals, print_json};
use anyhow::Result;
use std::path::{Path, PathBuf};
use texsyn::cache::Cache;
use texsyn::ops::pack::UnpackReport;

#[derive(clap::Args)]
pub struct PackArgs {
    config: PathBuf,
    #[arg(long = "set", value_name = "STAGE.KEY=VALUE")]
    sets: Vec<String>,
    /// The archive to write (e.g. results.tar.zst).
    #[arg(short, long, value_name = "ARCHIVE")]
    output: PathBuf,
}

#[derive(clap::Args)]
pub struct UnpackArgs {
    archive: PathBuf,
    /// Where to write the config, inputs, lock and outputs.
    #[arg(short, long, value_name = "DIR")]
    output: Option<PathBuf>,
}

/// `texsyn pack`.
pub fn pack(args: &PackArgs, g: &Globals) -> Result<i32> {
    let cache = Cache::open(&g.cache_dir)?;
    let report =
        texsyn::ops::pack::pack(&args.config, &args.sets, &cache, &args.output, g.progress)?;
    if g.json {
        print_json(&report)?;
    } else if !g.quiet {
        println!(
            "packed {} objects ({} computed now), {} input files, {} outputs and the lock \
             into {} ({})",
            report.objects,
            report.computed,
            report.inputs,
            report.outputs,
            args.output.display(),
            texsyn::memory::human(report.bytes)
        );
    }
    Ok(0)
}

/// `texsyn unpack`.
pub fn unpack(args: &UnpackArgs, g: &Globals) -> Result<i32> {
    let report = texsyn::ops::pack::unpack(&args.archive, &g.cache_dir, args.output.as_deref())?;
    if g.json {
        print_json(&report)?;
    } else if !g.quiet {
        print_unpacked(&report, &g.cache_dir);
    }
    Ok(0)
}

/// What was imported and, when the run was written out, where, with the commands that check
/// it and run it again.
fn print_unpacked(report: &UnpackReport, cache_dir: &Path) {
    println!(
        "imported {} objects into {} ({} were there already)",
        report.imported,
        cache_dir.display(),
        report.present
    );
    if let (Some(config), Some(lock), Some(out)) = (&report.config, &report.lock, &report.outputs) {
        let sets: String = report
            .sets
            .iter()
            .map(|s| format!(" --set '{}'", s.replace('\'', "'\\''")))
            .collect();
        println!("config: {}", config.display());
        println!("outputs: {}", out.display());
        println!(
            "check: texsyn verify {} {} --cache {}   (--fresh recomputes)",
            config.display(),
            lock.display(),
            cache_dir.display()
        );
        println!(
            "rerun: texsyn run {}{sets} --cache {} --out {}",
            config.display(),
            cache_dir.display(),
            out.display()
        );
    }
}
