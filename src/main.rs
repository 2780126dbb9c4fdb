//! The `texsyn` command line: the global options, their setup (logging, threads, memory
//! budget), and one function per command (in [`cli`]). `main` reports the error and picks
//! the exit status.

mod cli;

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use std::path::PathBuf;
use texsyn::cache::parse_size;
use texsyn::pipeline::ProgressMode;

#[derive(Parser)]
#[command(
    name = "texsyn",
    version,
    about = "Texture synthesis on shapes from examples"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Cache directory. Default: $TEXSYN_CACHE, else ./cache.
    #[arg(long, global = true)]
    cache: Option<PathBuf>,
    /// Worker threads. Default: $RAYON_NUM_THREADS, else one per core. Results do not depend on it.
    #[arg(short = 'j', long = "jobs", global = true)]
    jobs: Option<usize>,
    /// Memory budget (e.g. 4GiB): a parameter whose estimated need is larger is refused
    /// before work starts, naming a value that fits. Default: half of the available memory
    /// (within a cgroup or Slurm limit, the room left under it).
    #[arg(long = "max-memory", global = true, value_name = "SIZE")]
    max_memory: Option<String>,
    /// Print nothing but errors.
    #[arg(short, long, global = true)]
    quiet: bool,
    /// Machine-readable output on stdout.
    #[arg(long, global = true)]
    json: bool,
    /// More log output (-v: info, -vv: debug).
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    verbose: u8,
}

#[derive(Subcommand)]
enum Command {
    /// Run a config: compute what is not cached, write the outputs.
    Run(cli::run::RunArgs),
    /// Run a sweep (README, "Sweeps"): a base config and axes over its values, one ordinary
    /// run per point in its own folder (OUT/points/NNN-values/), on one cache; then the
    /// results table (OUT/results.csv, .md, .json) and the sweep's lock (OUT/sweep.lock).
    /// Points already done (report present, everything cached) are not run again.
    Sweep(cli::sweep::SweepArgs),
    /// Show what `run` would compute, without computing (like make -n).
    Status(cli::status::StatusArgs),
    /// Print one line per artifact: node, key, content hash (computing what is missing).
    /// Redirect it into a lock file for `verify`, or write it with `-o`. The `--set`
    /// overrides are recorded in the lock (`# set:` lines), and `verify` applies them.
    Hashes(cli::hashes::HashesArgs),
    /// Check a config's artifacts against a lock file written by `hashes`, re-hashing every
    /// cached object. Exit status: 0 all match and nothing was damaged; 1 a mismatch (each is
    /// named); 3 all match, but damaged cache objects were found (each is named; they were
    /// recomputed and replaced). `--json` prints the mismatches and the damaged objects.
    /// The lock's recorded `--set` overrides apply first, then the command line's.
    Verify(cli::verify::VerifyArgs),
    /// Score a run's results against their exemplars (nearest-patch measures; README,
    /// "Scoring"). Runs what is not cached first, like `run`, but writes no outputs. With
    /// several configs (or --markdown), prints one table of all of them.
    Score(cli::score::ScoreArgs),
    /// Print the config's DAG in Graphviz DOT.
    Graph(cli::graph::GraphArgs),
    /// Render three views of a mesh (textured through its OBJ texture coordinates) to a PNG.
    Render(cli::render::RenderArgs),
    /// Pack a run into one archive (README, "Packing a run"): the config, its input files,
    /// the lock file, every node's cached artifact and the outputs, in a zstd-compressed tar.
    /// Computes what is not cached first, and re-hashes every cached object.
    Pack(cli::pack::PackArgs),
    /// Import a `pack` archive into the cache, after checking every entry's hash and that every
    /// object's key is one the packed config's graph produces; a damaged or foreign archive
    /// is refused and nothing is imported. With `-o DIR`, also writes the config, its inputs,
    /// its lock (NAME.lock beside the config) and the outputs (DIR/out/NAME/).
    Unpack(cli::pack::UnpackArgs),
    /// Trim the cache to a size, least recently used objects first.
    Gc(cli::gc::GcArgs),
    /// Write one self-contained HTML page of a run (the config is run first, as `run` does)
    /// or of a sweep's folder: the DAG with each node's status, time, size, key and hash, the
    /// inputs and previews, a 3D view of the .glb outputs, scores and the lock's verdict; for
    /// a sweep a gallery and a sortable, filterable results table. Opens from disk, no network.
    Report(cli::report::ReportArgs),
    /// Run a config, then rerun it whenever the config or an input file it reads changes,
    /// saying which nodes reran and rewriting the outputs and report.html. With --serve PORT
    /// the report is served on 127.0.0.1 and reloads itself after each rerun. Ctrl-C stops.
    Watch(cli::watch::WatchArgs),
}

fn main() {
    let code = match real_main() {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {}", error_text(&e));
            1
        }
    };
    std::process::exit(code);
}

/// The error and its causes, skipping causes whose text the message already includes (our
/// error types put their source's text in their own message).
fn error_text(e: &anyhow::Error) -> String {
    let mut text = e.to_string();
    for cause in e.chain().skip(1) {
        let c = cause.to_string();
        if !text.contains(&c) {
            text = format!("{text}: {c}");
        }
    }
    text
}

/// Parses the command line, sets up logging, the memory budget and the thread count, and
/// runs the command. Its exit status.
fn real_main() -> Result<i32> {
    let cli = Cli::parse();
    let level = match (cli.quiet, cli.verbose) {
        (true, _) => tracing::Level::ERROR,
        (false, 0) => tracing::Level::WARN,
        (false, 1) => tracing::Level::INFO,
        _ => tracing::Level::DEBUG,
    };
    tracing_subscriber::fmt()
        .with_max_level(level)
        .with_writer(std::io::stderr)
        .without_time()
        .with_target(false)
        .init();
    if let Some(m) = &cli.max_memory {
        let bytes = parse_size(m).map_err(|e| anyhow::anyhow!("--max-memory {m}: {e}"))?;
        if bytes == 0 {
            bail!("--max-memory must be more than 0");
        }
        texsyn::memory::set_budget(bytes);
    }
    if let Some(j) = cli.jobs {
        if j == 0 {
            bail!("-j must be at least 1");
        }
        rayon::ThreadPoolBuilder::new()
            .num_threads(j)
            .build_global()
            .context("setting the thread count")?;
    }
    let g = cli::Globals {
        cache_dir: cli
            .cache
            .clone()
            .or_else(|| std::env::var_os("TEXSYN_CACHE").map(PathBuf::from))
            .unwrap_or_else(|| PathBuf::from("cache")),
        progress: ProgressMode::for_stderr(cli.quiet || cli.json),
        quiet: cli.quiet,
        json: cli.json,
        jobs: cli.jobs,
    };
    match &cli.command {
        Command::Run(args) => cli::run::run(args, &g),
        Command::Sweep(args) => cli::sweep::sweep(args, &g),
        Command::Status(args) => cli::status::status(args, &g),
        Command::Hashes(args) => cli::hashes::hashes(args, &g),
        Command::Verify(args) => cli::verify::verify(args, &g),
        Command::Score(args) => cli::score::score(args, &g),
        Command::Graph(args) => cli::graph::graph(args, &g),
        Command::Render(args) => cli::render::render(args, &g),
        Command::Pack(args) => cli::pack::pack(args, &g),
        Command::Unpack(args) => cli::pack::unpack(args, &g),
        Command::Gc(args) => cli::gc::gc(args, &g),
        Command::Report(args) => cli::report::report(args, &g),
        Command::Watch(args) => cli::watch::watch(args, &g),
    }
}
