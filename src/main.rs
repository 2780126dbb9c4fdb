//! The `texsyn` command line. `main` only calls [`real_main`] and reports its error.

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use std::path::{Path, PathBuf};
use std::time::Instant;
use texsyn::cache::{Cache, parse_size};
use texsyn::config::Config;
use texsyn::methods::Plan;
use texsyn::ops::lockfile::LockFile;
use texsyn::ops::sweep::Sweep;
use texsyn::pipeline::{self, ProgressMode, RunOptions, RunResult, Shard, outputs};

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
    Run {
        config: PathBuf,
        /// Override a config value: --set synthesize.seed=2 (repeatable).
        #[arg(long = "set", value_name = "STAGE.KEY=VALUE")]
        sets: Vec<String>,
        /// Output directory. Default: out/<config name>.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Also write the `--json` report to this file (atomically): what a sweep's table is
        /// made from.
        #[arg(long, value_name = "FILE")]
        report: Option<PathBuf>,
        /// Compute only shard i of N of a `solid` run (counting from 0): its share of the
        /// finest bricks and the coarser bricks they depend on, into the cache; no outputs
        /// are written. A later run without --shard (the gather) assembles the outputs from
        /// the cached bricks (README, "Sharded solid runs").
        #[arg(long, value_name = "i/N", conflicts_with = "out")]
        shard: Option<String>,
    },
    /// Run a sweep (README, "Sweeps"): a base config and axes over its values, one ordinary
    /// run per point in its own folder (OUT/points/NNN-values/), on one cache; then the
    /// results table (OUT/results.csv, .md, .json) and the sweep's lock (OUT/sweep.lock).
    /// Points already done (report present, everything cached) are not run again.
    Sweep {
        sweep: PathBuf,
        /// Say what would run, point by point, and run nothing (like `status`).
        #[arg(long)]
        status: bool,
        /// Where points run: `local` (processes side by side on this machine) or `slurm`
        /// (one job array; the cache must be on a filesystem the compute nodes see).
        #[arg(long, default_value = "local")]
        executor: String,
        /// Local executor: points run at once. Default: the sweep's `workers`, else one per
        /// core (at most the number of points); the cores are shared among them.
        #[arg(long)]
        workers: Option<usize>,
        /// The sweep's folder. Default: out/<sweep name>.
        #[arg(long)]
        out: Option<PathBuf>,
        #[command(flatten)]
        slurm: SlurmFlags,
    },
    /// Show what `run` would compute, without computing (like make -n).
    Status {
        config: PathBuf,
        #[arg(long = "set", value_name = "STAGE.KEY=VALUE")]
        sets: Vec<String>,
        /// Also say what `run --shard i/N` would compute: its finest bricks and, when the
        /// synthesis' inputs are cached, the bricks per level it would compute.
        #[arg(long, value_name = "i/N")]
        shard: Option<String>,
    },
    /// Print one line per artifact: node, key, content hash (computing what is missing).
    /// Redirect it into a lock file for `verify`, or write it with `-o`. The `--set`
    /// overrides are recorded in the lock (`# set:` lines), and `verify` applies them.
    Hashes {
        config: PathBuf,
        #[arg(long = "set", value_name = "STAGE.KEY=VALUE")]
        sets: Vec<String>,
        /// Write the lock file here (atomically) instead of printing it. An existing lock whose
        /// line for a node has the same key but another content hash (a code change without
        /// a version bump) is not overwritten unless `--accept-unbumped` is given.
        #[arg(short, long, value_name = "LOCKFILE")]
        output: Option<PathBuf>,
        /// With `-o`: overwrite lines whose content changed under an unchanged key.
        #[arg(long, requires = "output")]
        accept_unbumped: bool,
    },
    /// Check a config's artifacts against a lock file written by `hashes`, re-hashing every
    /// cached object. Exit status: 0 all match and nothing was damaged; 1 a mismatch (each is
    /// named); 3 all match, but damaged cache objects were found (each is named; they were
    /// recomputed and replaced). `--json` prints the mismatches and the damaged objects.
    /// The lock's recorded `--set` overrides apply first, then the command line's.
    Verify {
        config: PathBuf,
        lockfile: PathBuf,
        #[arg(long = "set", value_name = "STAGE.KEY=VALUE")]
        sets: Vec<String>,
        /// Recompute everything in an empty temporary cache instead of re-reading the cache.
        #[arg(long)]
        fresh: bool,
    },
    /// Score a run's results against their exemplars (nearest-patch measures; README,
    /// "Scoring"). Runs what is not cached first, like `run`, but writes no outputs. With
    /// several configs (or --markdown), prints one table of all of them.
    Score {
        #[arg(required = true)]
        configs: Vec<PathBuf>,
        #[arg(long = "set", value_name = "STAGE.KEY=VALUE")]
        sets: Vec<String>,
        /// Print a Markdown table (BENCHMARKS.md's quality table).
        #[arg(long)]
        markdown: bool,
    },
    /// Print the config's DAG in Graphviz DOT.
    Graph {
        config: PathBuf,
        #[arg(long = "set", value_name = "STAGE.KEY=VALUE")]
        sets: Vec<String>,
    },
    /// Render three views of a mesh (textured through its OBJ texture coordinates) to a PNG.
    Render {
        mesh: PathBuf,
        /// Texture image for the mesh's texture coordinates. Without it an OBJ's materials'
        /// `map_Kd` images (beside the OBJ) are used, one per material: every page of a baked
        /// atlas.
        #[arg(long)]
        texture: Option<PathBuf>,
        /// Output PNG.
        #[arg(short, long)]
        output: PathBuf,
        /// Side of each view in pixels.
        #[arg(long, default_value_t = 512)]
        size: u32,
        /// Up axis: x, y, z, -x, -y or -z.
        #[arg(long, default_value = "y")]
        up: String,
    },
    /// Pack a run into one archive (README, "Packing a run"): the config, its input files,
    /// the lock file, every node's cached artifact and the outputs, in a zstd-compressed tar.
    /// Computes what is not cached first, and re-hashes every cached object.
    Pack {
        config: PathBuf,
        #[arg(long = "set", value_name = "STAGE.KEY=VALUE")]
        sets: Vec<String>,
        /// The archive to write (e.g. results.tar.zst).
        #[arg(short, long, value_name = "ARCHIVE")]
        output: PathBuf,
    },
    /// Import a `pack` archive into the cache, after checking every entry's hash and that every
    /// object's key is one the packed config's graph produces; a damaged or foreign archive
    /// is refused and nothing is imported. With `-o DIR`, also writes the config, its inputs,
    /// its lock (NAME.lock beside the config) and the outputs (DIR/out/NAME/).
    Unpack {
        archive: PathBuf,
        /// Where to write the config, inputs, lock and outputs.
        #[arg(short, long, value_name = "DIR")]
        output: Option<PathBuf>,
    },
    /// Trim the cache to a size, least recently used objects first.
    Gc {
        /// Budget, e.g. 500M or 2G.
        #[arg(long)]
        max_size: String,
    },
}

/// `--executor slurm`'s options; each overrides the sweep's `[slurm]` value of that name.
#[derive(clap::Args, Debug, Default)]
struct SlurmFlags {
    /// Slurm partition.
    #[arg(long)]
    partition: Option<String>,
    /// Slurm time limit per task (e.g. 30, 1:00:00, 1-00:00).
    #[arg(long)]
    time: Option<String>,
    /// Slurm memory per task (e.g. 4G); also each task's memory budget (--max-memory).
    #[arg(long)]
    mem: Option<String>,
    /// Slurm CPUs per task; also each task's thread count.
    #[arg(long)]
    cpus_per_task: Option<u32>,
    /// Slurm account.
    #[arg(long)]
    account: Option<String>,
}

/// The sweep's `[slurm]` table with the command line's flags over it, checked.
fn slurm_options(sweep: &Sweep, flags: &SlurmFlags) -> Result<texsyn::ops::slurm::SlurmOptions> {
    use serde::Deserialize;
    let mut opts = match &sweep.slurm {
        Some(t) => texsyn::ops::slurm::SlurmOptions::deserialize(toml::Value::Table(t.clone()))
            .map_err(|e| {
                anyhow::anyhow!(
                    "{}: [slurm]: {}",
                    sweep.path.display(),
                    e.to_string().trim()
                )
            })?,
        None => Default::default(),
    };
    if let Some(p) = &flags.partition {
        opts.partition = Some(p.clone());
    }
    if let Some(t) = &flags.time {
        opts.time = Some(t.clone());
    }
    if let Some(m) = &flags.mem {
        opts.mem = Some(parse_size(m).map_err(|e| anyhow::anyhow!("--mem {m}: {e}"))?);
    }
    if let Some(c) = flags.cpus_per_task {
        opts.cpus_per_task = Some(c);
    }
    if let Some(a) = &flags.account {
        opts.account = Some(a.clone());
    }
    opts.check()?;
    Ok(opts)
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
    let cache_dir = cli
        .cache
        .clone()
        .or_else(|| std::env::var_os("TEXSYN_CACHE").map(PathBuf::from))
        .unwrap_or_else(|| PathBuf::from("cache"));
    let progress = if cli.quiet || cli.json {
        ProgressMode::Hidden
    } else {
        ProgressMode::Bars
    };
    match &cli.command {
        Command::Run {
            config,
            sets,
            out,
            report: report_file,
            shard: Some(shard),
        } => {
            let start = Instant::now();
            let shard: Shard = shard.parse()?;
            let plan = load_shardable_plan(config, sets)?;
            let cache = Cache::open(&cache_dir)?;
            let opts = RunOptions {
                progress,
                verify_all: false,
            };
            let _ = out; // refused by clap alongside --shard
            let result = pipeline::run_shard(&plan.dag, &cache, opts, shard, false)?;
            let seconds = start.elapsed().as_secs_f64();
            let mut report = serde_json::to_value(&result)?;
            report["outputs"] = serde_json::json!([]);
            report["seconds"] = serde_json::json!(seconds);
            report["peak_memory_bytes"] = serde_json::json!(texsyn::memory::peak_resident());
            report["sets"] = serde_json::json!(sets);
            report["shard"] = serde_json::json!(shard.to_string());
            if let Some(f) = report_file {
                write_atomic(f, serde_json::to_string_pretty(&report)?.as_bytes())?;
            }
            if cli.json {
                println!("{}", serde_json::to_string_pretty(&report)?);
            } else if !cli.quiet {
                print_table(&result.nodes);
                print_shard(&result, config, false);
                println!("no outputs written (shard {shard}) in {seconds:.3} s");
            }
            Ok(0)
        }
        Command::Run {
            config,
            sets,
            out,
            report: report_file,
            ..
        } => {
            let start = Instant::now();
            let plan = load_plan(config, sets)?;
            let out_dir = out.clone().unwrap_or(plan.default_out.clone());
            // A swap a killed run left half done is finished (or undone) before anything else.
            outputs::recover(&out_dir).context("recovering the output directory")?;
            let result = run_plan(&plan, &cache_dir, progress)?;
            // One run's exports are written as one set: all of them, or none on an error.
            let bundles: Vec<_> = plan
                .dag
                .nodes
                .iter()
                .zip(&result.artifacts)
                .filter(|(node, _)| node.exports)
                .map(|(_, a)| a)
                .collect();
            let written = outputs::materialize_all(&bundles, &out_dir).with_context(|| {
                format!(
                    "writing the outputs into {} (it still holds the previous run's outputs)",
                    out_dir.display()
                )
            })?;
            // Scores when the config asks for them (`[score]`, enabled).
            let scores = match plan.score.as_ref().filter(|s| s.enabled) {
                Some(section) => Some(score_plan(config, sets, &plan, &result, section)?),
                None => None,
            };
            let seconds = start.elapsed().as_secs_f64();
            let outputs: Vec<_> = written
                .iter()
                .map(|(p, w)| serde_json::json!({ "path": p, "written": w }))
                .collect();
            let mut report = serde_json::json!({
                "nodes": result.reports,
                "outputs": outputs,
                "warnings": result.warnings,
                "seconds": seconds,
                "peak_memory_bytes": texsyn::memory::peak_resident(),
                "sets": sets,
            });
            if let Some(s) = &scores {
                report["scores"] = serde_json::to_value(s)?;
            }
            if let Some(f) = report_file {
                write_atomic(f, serde_json::to_string_pretty(&report)?.as_bytes())?;
            }
            if cli.json {
                println!("{}", serde_json::to_string_pretty(&report)?);
            } else if !cli.quiet {
                print_table(&result.reports);
                if let Some(s) = &scores {
                    print!("{}", texsyn::score::report_text(s));
                }
                let changed = written.iter().filter(|w| w.1).count();
                println!(
                    "outputs: {} ({} written, {} unchanged) in {:.3} s",
                    out_dir.display(),
                    changed,
                    written.len() - changed,
                    seconds
                );
            }
            Ok(0)
        }
        Command::Sweep {
            sweep,
            status,
            executor,
            workers,
            out,
            slurm,
        } => sweep_command(
            &cli,
            SweepArgs {
                path: sweep,
                status_only: *status,
                executor,
                workers: *workers,
                out: out.as_deref(),
                slurm_flags: slurm,
            },
            &cache_dir,
        ),
        Command::Status {
            config,
            sets,
            shard,
        } => {
            let shard: Option<Shard> = shard.as_deref().map(str::parse).transpose()?;
            let plan = match shard {
                Some(_) => load_shardable_plan(config, sets)?,
                None => load_plan(config, sets)?,
            };
            let cache = Cache::open(&cache_dir)?;
            let lines = pipeline::status(&plan.dag, &cache);
            let opts = RunOptions::default();
            let planned = shard
                .map(|s| pipeline::run_shard(&plan.dag, &cache, opts, s, true))
                .transpose()?;
            if cli.json {
                match &planned {
                    Some(p) => println!(
                        "{}",
                        serde_json::to_string_pretty(&serde_json::json!({
                            "nodes": lines,
                            "shard": p,
                        }))?
                    ),
                    None => println!("{}", serde_json::to_string_pretty(&lines)?),
                }
            } else {
                println!("{:<24} {:<17} {:<20} state", "node", "stage", "algorithm");
                for l in &lines {
                    let state = match l.state {
                        "cached" => "cached",
                        "run" => "would run",
                        _ => "would run if its inputs change",
                    };
                    println!("{:<24} {:<17} {:<20} {state}", l.node, l.stage, l.algorithm);
                }
                if let Some(p) = &planned {
                    print_shard(p, config, true);
                }
            }
            Ok(0)
        }
        Command::Hashes {
            config,
            sets,
            output,
            accept_unbumped,
        } => {
            if Sweep::is_sweep_file(config) {
                return sweep_hashes(config, sets, output.as_deref(), &cache_dir, progress);
            }
            let (_, result) = run_config(config, sets, &cache_dir, progress)?;
            let now = LockFile::of_reports(&result.reports, sets);
            let Some(output) = output else {
                print!("{}", now.to_text());
                return Ok(0);
            };
            if output.exists() {
                let unbumped: Vec<_> = LockFile::read(output)?
                    .compare(&now)
                    .into_iter()
                    .filter(|d| d.is_unbumped())
                    .collect();
                for d in &unbumped {
                    eprintln!("unbumped: {d}");
                }
                if !unbumped.is_empty() && !accept_unbumped {
                    bail!(
                        "{} line(s) of {} would change content under an unchanged key; bump the \
                         version of each node's algorithm (README, \"When to bump a version\"), \
                         or pass --accept-unbumped if the change is meant (the lock was not \
                         written)",
                        unbumped.len(),
                        output.display()
                    );
                }
            }
            write_atomic(output, now.to_text().as_bytes())?;
            Ok(0)
        }
        Command::Verify {
            config,
            lockfile,
            sets,
            fresh,
        } => {
            if Sweep::is_sweep_file(config) {
                return sweep_verify(config, lockfile, sets, *fresh, &cache_dir, progress, &cli);
            }
            let text = texsyn::ops::lockfile::read_text(lockfile)?;
            if texsyn::ops::sweep::lock::SweepLock::is_sweep_lock(&text) {
                bail!(
                    "{} is a sweep's lock, and {} is not a sweep: verify the sweep file with it",
                    lockfile.display(),
                    config.display()
                );
            }
            let lock = LockFile::parse(&text, lockfile)?;
            // The lock's recorded overrides first, so the command line's own win.
            let sets: Vec<String> = lock.sets.iter().chain(sets.iter()).cloned().collect();
            let plan = load_plan(config, &sets)?;
            let temp = fresh.then(|| outputs::TempDir::new("texsyn-verify"));
            let cache = match &temp {
                Some(t) => Cache::open(t.path())?,
                // Verifying a cache that is not there (a mistyped --cache) is an error, not
                // a new cache.
                None => Cache::open_existing(&cache_dir)?,
            };
            let result = pipeline::run(
                &plan.dag,
                &cache,
                RunOptions {
                    progress,
                    verify_all: true,
                },
            )?;
            let differences = lock.compare(&LockFile::of_reports(&result.reports, &sets));
            // Nodes whose content changed under an unchanged key (a missing version bump).
            let unbumped: Vec<&str> = differences
                .iter()
                .filter_map(|d| match d {
                    texsyn::ops::lockfile::Difference::ContentChangedUnderSameKey {
                        node, ..
                    } => Some(node.as_str()),
                    _ => None,
                })
                .collect();
            let problems: Vec<String> = differences.iter().map(|d| d.to_string()).collect();
            let code = if !problems.is_empty() {
                VERIFY_MISMATCH
            } else if !result.damaged.is_empty() {
                VERIFY_DAMAGED
            } else {
                0
            };
            if cli.json {
                println!(
                    "{}",
                    serde_json::to_string_pretty(&serde_json::json!({
                        "lockfile": lockfile,
                        "artifacts": result.reports.len(),
                        "mismatches": problems,
                        "unbumped": unbumped,
                        "damaged": result.damaged,
                        "exit_code": code,
                    }))?
                );
            }
            print_verify_problems(&result.damaged, &problems, lockfile);
            if !problems.is_empty() {
                // Named above.
            } else if !result.damaged.is_empty() {
                eprintln!(
                    "{} damaged cache object(s), recomputed and replaced; all {} artifacts now match {}",
                    result.damaged.len(),
                    result.reports.len(),
                    lockfile.display()
                );
            } else if !cli.quiet && !cli.json {
                println!(
                    "verified: {} artifacts match {}",
                    result.reports.len(),
                    lockfile.display()
                );
            }
            Ok(code)
        }
        Command::Score {
            configs,
            sets,
            markdown,
        } => {
            let mut reports = Vec::new();
            for config in configs {
                // A glob over a config folder also meets the files configs name (curves):
                // with several files, one without `method` is passed over, said on stderr.
                if configs.len() > 1
                    && Config::load(config, &[]).is_ok_and(|c| !c.table.contains_key("method"))
                {
                    eprintln!(
                        "{}: no `method`, not a config; passed over",
                        config.display()
                    );
                    continue;
                }
                let (plan, result) = run_config(config, sets, &cache_dir, progress)?;
                let section = plan.score.clone().unwrap_or_default();
                let cfg = Config::load(config, sets)?;
                // A solid surface has no planar image: a section of the same solid is
                // synthesized (from the cached bricks where they overlap) and scored.
                let report = match texsyn::score::solid::substitute_section(&plan, &result, &cfg) {
                    Some(set) => {
                        let mut with = sets.clone();
                        with.push(set.clone());
                        let (plan2, result2) = run_config(config, &with, &cache_dir, progress)?;
                        let mut r = score_plan(config, &with, &plan2, &result2, &section)?;
                        for item in &mut r.items {
                            item.output = format!("{} (a section made for scoring)", item.output);
                            item.notes.push(format!(
                                "the config requests the surface; this is a section synthesized for scoring (--set '{set}')"
                            ));
                        }
                        r
                    }
                    None => score_plan(config, sets, &plan, &result, &section)?,
                };
                reports.push(report);
            }
            if cli.json {
                if reports.len() == 1 && !*markdown {
                    println!("{}", serde_json::to_string_pretty(&reports[0])?);
                } else {
                    println!("{}", serde_json::to_string_pretty(&reports)?);
                }
            } else if *markdown || reports.len() > 1 {
                print!("{}", texsyn::score::markdown_table(&reports));
            } else if !cli.quiet {
                print!("{}", texsyn::score::report_text(&reports[0]));
            }
            Ok(0)
        }
        Command::Graph { config, sets } => {
            let plan = load_plan(config, sets)?;
            print!("{}", plan.dag.to_dot());
            Ok(0)
        }
        Command::Render {
            mesh,
            texture,
            output,
            size,
            up,
        } => {
            let up = parse_axis(up)?;
            let opts = texsyn::render::views::ViewOptions {
                size: *size,
                up,
                ..Default::default()
            };
            let img = texsyn::render::load::render_mesh_file(mesh, texture.as_deref(), &opts)?;
            let png = texsyn::stages::reconstruct::textured_export::encode_png(&img, false);
            write_atomic(output, &png)?;
            if !cli.quiet {
                println!("wrote {}", output.display());
            }
            Ok(0)
        }
        Command::Pack {
            config,
            sets,
            output,
        } => {
            let cache = Cache::open(&cache_dir)?;
            let report = texsyn::ops::pack::pack(config, sets, &cache, output, progress)?;
            if cli.json {
                println!("{}", serde_json::to_string_pretty(&report)?);
            } else if !cli.quiet {
                println!(
                    "packed {} objects ({} computed now), {} input files, {} outputs and the lock \
                     into {} ({})",
                    report.objects,
                    report.computed,
                    report.inputs,
                    report.outputs,
                    output.display(),
                    texsyn::memory::human(report.bytes)
                );
            }
            Ok(0)
        }
        Command::Unpack { archive, output } => {
            let report = texsyn::ops::pack::unpack(archive, &cache_dir, output.as_deref())?;
            if cli.json {
                println!("{}", serde_json::to_string_pretty(&report)?);
            } else if !cli.quiet {
                println!(
                    "imported {} objects into {} ({} were there already)",
                    report.imported,
                    cache_dir.display(),
                    report.present
                );
                if let (Some(config), Some(lock), Some(out)) =
                    (&report.config, &report.lock, &report.outputs)
                {
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
            Ok(0)
        }
        Command::Gc { max_size } => {
            let budget = parse_size(max_size)?;
            // A mistyped --cache is an error, not a new empty cache; an object that cannot be
            // removed is an error naming it.
            let cache = Cache::open_existing(&cache_dir)?;
            let report = cache.gc(budget)?;
            if !cli.quiet {
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
    }
}

/// `verify`'s report on stderr: each damaged object (already recomputed and replaced), each
/// mismatch, and how many mismatches there were.
fn print_verify_problems(
    damaged: &[pipeline::executor::Damage],
    problems: &[String],
    lockfile: &Path,
) {
    for d in damaged {
        eprintln!(
            "damaged: {}: {} ({}); recomputed and replaced",
            d.node,
            d.path.display(),
            d.problem
        );
    }
    for p in problems {
        eprintln!("mismatch: {p}");
    }
    if !problems.is_empty() {
        eprintln!(
            "{} mismatch(es) against {}",
            problems.len(),
            lockfile.display()
        );
    }
}

/// `verify`'s exit status when an artifact differs from the lock file.
const VERIFY_MISMATCH: i32 = 1;
/// `verify`'s exit status when every artifact matches but damaged cache objects were found
/// (and recomputed and replaced).
const VERIFY_DAMAGED: i32 = 3;

/// Loads `config` with the `--set` overrides and plans its DAG.
fn load_plan(config: &Path, sets: &[String]) -> Result<Plan> {
    let cfg = Config::load(config, sets)?;
    Ok(texsyn::methods::plan(&cfg)?)
}

/// [`load_plan`], for a run split into shards: only a config with a node that splits its
/// work into pieces (the `solid` method's synthesis) can be.
fn load_shardable_plan(config: &Path, sets: &[String]) -> Result<Plan> {
    let plan = load_plan(config, sets)?;
    if !plan.dag.nodes.iter().any(|n| n.splits_into_shards()) {
        bail!(
            "{}: --shard splits the bricks of a `solid` run among machines; method `{}` has no \
             work that can be split (run it without --shard)",
            config.display(),
            plan.method
        );
    }
    Ok(plan)
}

/// What a shard did (or, from `status`, would do), after the node table.
fn print_shard(result: &pipeline::ShardResult, config: &Path, planning: bool) {
    let shard = result.shard;
    if result.sharded.is_empty() {
        println!(
            "shard {shard}: the inputs of the synthesis are not all cached yet; the shard \
             computes them first, and its share of bricks is known then"
        );
    }
    for s in &result.sharded {
        let share = &s.share;
        let n = |k: &str| share[k].as_u64().unwrap_or(0);
        let assigned = share["assigned"].as_array().map_or(0, Vec::len);
        let levels = share["levels"].as_array().cloned().unwrap_or_default();
        let per_level = |k: &str| {
            levels
                .iter()
                .map(|l| l[k].as_u64().unwrap_or(0).to_string())
                .collect::<Vec<_>>()
                .join(" ")
        };
        println!(
            "{}: shard {shard}: {assigned} of {} finest bricks; bricks per level, coarsest \
             first: needed {}, {} {}, {} in the cache",
            s.node,
            n("finest_bricks"),
            per_level("bricks_needed"),
            if share["from_empty_cache"].is_null() {
                "computed"
            } else {
                "to compute"
            },
            per_level("bricks_computed"),
            per_level("bricks_reused"),
        );
        if let Some(fresh) = share["from_empty_cache"].as_array() {
            let fresh: Vec<String> = fresh.iter().map(|v| v.to_string()).collect();
            println!(
                "{}: shard {shard} from an empty cache: {} bricks per level",
                s.node,
                fresh.join(" ")
            );
        }
    }
    // Planning, the skipped nodes include those not cached yet (the table above says which).
    if !result.skipped.is_empty() && !planning {
        println!(
            "left to the gather run (`texsyn run {}` without --shard, after all {} shards): {}",
            config.display(),
            shard.count,
            result.skipped.join(", ")
        );
    }
}

/// Plans `config` and runs it in the cache at `cache_dir`, computing what is not cached
/// (`run` and `hashes`).
fn run_config(
    config: &Path,
    sets: &[String],
    cache_dir: &Path,
    progress: ProgressMode,
) -> Result<(Plan, RunResult)> {
    let plan = load_plan(config, sets)?;
    let result = run_plan(&plan, cache_dir, progress)?;
    Ok((plan, result))
}

/// Scores a run of `config` (see `texsyn::score`).
fn score_plan(
    config: &Path,
    sets: &[String],
    plan: &Plan,
    result: &RunResult,
    section: &texsyn::score::ScoreSection,
) -> Result<texsyn::score::Report> {
    let cfg = Config::load(config, sets)?;
    texsyn::score::score_run(&cfg, plan, result, section)
        .with_context(|| format!("scoring {}", config.display()))
}

/// Runs a planned DAG in the cache at `cache_dir`, computing what is not cached.
fn run_plan(plan: &Plan, cache_dir: &Path, progress: ProgressMode) -> Result<RunResult> {
    let cache = Cache::open(cache_dir)?;
    Ok(pipeline::run(
        &plan.dag,
        &cache,
        RunOptions {
            progress,
            verify_all: false,
        },
    )?)
}

fn parse_axis(s: &str) -> Result<glam::Vec3> {
    Ok(match s {
        "x" | "+x" => glam::Vec3::X,
        "y" | "+y" => glam::Vec3::Y,
        "z" | "+z" => glam::Vec3::Z,
        "-x" => -glam::Vec3::X,
        "-y" => -glam::Vec3::Y,
        "-z" => -glam::Vec3::Z,
        other => bail!("--up {other:?}: expected x, y, z, -x, -y or -z"),
    })
}

fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let tmp = dir.join(format!(
        ".{}.tmp-{}",
        path.file_name()
            .map(|n| n.to_string_lossy())
            .unwrap_or_default(),
        std::process::id()
    ));
    let written = std::fs::write(&tmp, bytes)
        .with_context(|| format!("writing {}", tmp.display()))
        .and_then(|()| {
            std::fs::rename(&tmp, path).with_context(|| format!("writing {}", path.display()))
        });
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

fn print_table(reports: &[pipeline::NodeReport]) {
    // The pieces column appears only when a node caches pieces (the solid's bricks).
    let pieces = reports.iter().any(|r| r.pieces.is_some());
    println!(
        "{:<24} {:<17} {:<7} {:>9} {:>11}{}",
        "node",
        "stage",
        "status",
        "seconds",
        "bytes",
        if pieces {
            "  pieces computed / reused"
        } else {
            ""
        }
    );
    for r in reports {
        let status = match r.status {
            pipeline::NodeStatus::Cached => "cached",
            pipeline::NodeStatus::Ran => "ran",
        };
        let piece_counts = r
            .pieces
            .map(|p| format!("  {} / {}", p.computed, p.reused))
            .unwrap_or_default();
        println!(
            "{:<24} {:<17} {:<7} {:>9.3} {:>11}{piece_counts}",
            r.node,
            r.stage,
            status,
            r.seconds,
            texsyn::memory::human(r.bytes)
        );
    }
}

/// `texsyn sweep`'s command line.
struct SweepArgs<'a> {
    path: &'a Path,
    status_only: bool,
    executor: &'a str,
    workers: Option<usize>,
    out: Option<&'a Path>,
    slurm_flags: &'a SlurmFlags,
}

/// `texsyn sweep`: checks every point, says or runs what is not done, then writes the table
/// and the sweep's lock.
fn sweep_command(cli: &Cli, args: SweepArgs, cache_dir: &Path) -> Result<i32> {
    let SweepArgs {
        path,
        status_only,
        executor,
        workers,
        out,
        slurm_flags,
    } = args;
    use texsyn::ops::sweep::{
        CommonArgs, PointState, SweepDir, local, lock::SweepLock, point_state, slurm_executor,
        table,
    };
    if !matches!(executor, "local" | "slurm") {
        bail!("--executor {executor:?}: expected `local` or `slurm`");
    }
    let sweep = Sweep::load(path)?;
    let dir = SweepDir::new(
        &out.map(Path::to_owned)
            .unwrap_or_else(|| sweep.default_out()),
    );
    let cache = Cache::open(cache_dir)?;
    let mut states = Vec::new();
    for p in &sweep.points {
        states.push(point_state(&sweep, &dir, p, &cache)?);
    }
    let todo: Vec<&texsyn::ops::sweep::Point> = sweep
        .points
        .iter()
        .zip(&states)
        .filter(|(_, s)| **s != PointState::Done)
        .map(|(p, _)| p)
        .collect();
    if status_only {
        if cli.json {
            let lines: Vec<_> = sweep
                .points
                .iter()
                .zip(&states)
                .map(|(p, s)| {
                    serde_json::json!({ "point": p.index, "values": p.label(), "out": dir.point_out(p), "status": s })
                })
                .collect();
            println!("{}", serde_json::to_string_pretty(&lines)?);
        } else {
            for (p, s) in sweep.points.iter().zip(&states) {
                let what = match s {
                    PointState::Done => "done".to_owned(),
                    PointState::WouldRun { nodes } if nodes.is_empty() => {
                        "would run (everything cached; writes its outputs)".to_owned()
                    }
                    PointState::WouldRun { nodes } => format!("would compute {}", nodes.join(", ")),
                };
                println!("{:>4}  {:<40} {what}", p.index, p.label());
            }
            println!(
                "{} of {} points to run, in {}",
                todo.len(),
                sweep.points.len(),
                dir.root.display()
            );
        }
        return Ok(0);
    }
    let exe = std::env::current_exe().context("finding the texsyn binary")?;
    let cache_abs = std::path::absolute(cache_dir).unwrap_or_else(|_| cache_dir.to_owned());
    let quiet = cli.quiet || cli.json;
    let start = Instant::now();
    if !quiet && todo.len() < sweep.points.len() {
        println!(
            "{} of {} points done already; running {}",
            sweep.points.len() - todo.len(),
            sweep.points.len(),
            todo.len()
        );
    }
    let failures = if executor == "slurm" {
        let opts = slurm_options(&sweep, slurm_flags)?;
        let common = CommonArgs {
            cache: cache_abs.clone(),
            threads: Some(opts.cpus_per_task.unwrap_or(1) as usize),
            // A task's budget is the job's memory, when the sweep says it.
            max_memory: opts.mem,
        };
        let list = slurm_executor::TaskList::new(&exe, &sweep, &dir, &common);
        let mut last = String::new();
        let mut progress = |s: &[texsyn::ops::slurm::TaskOutcome]| {
            if quiet {
                return;
            }
            let active = s
                .iter()
                .filter(|t| matches!(t.status, texsyn::ops::slurm::TaskStatus::Active(_)))
                .count();
            let ended = s
                .iter()
                .filter(|t| {
                    matches!(
                        t.status,
                        texsyn::ops::slurm::TaskStatus::Exited(_)
                            | texsyn::ops::slurm::TaskStatus::Lost { .. }
                    )
                })
                .count();
            let line = format!("slurm: {active} tasks pending or running, {ended} ended");
            if line != last {
                println!("{line}");
                last = line;
            }
        };
        if slurm_executor::reattach(&dir, &mut progress)? && !quiet {
            println!("re-attached to the tasks an earlier `texsyn sweep` left in the queue");
        }
        // What is still to do once those have ended.
        let mut todo = Vec::new();
        for p in &sweep.points {
            if point_state(&sweep, &dir, p, &cache)? != PointState::Done {
                todo.push(p);
            }
        }
        if todo.is_empty() {
            Default::default()
        } else {
            if !quiet {
                println!(
                    "submitting {} points to Slurm ({} tasks); state in {}",
                    todo.len(),
                    todo.len() * list.per_point,
                    slurm_executor::state_dir(&dir).display()
                );
            }
            for p in &todo {
                dir.clear_reports(p, sweep.shards.unwrap_or(1));
            }
            slurm_executor::run(&list, &dir, &todo, &cache_abs, &opts, &mut progress)?
        }
    } else {
        let cores = cli.jobs.unwrap_or_else(|| {
            std::thread::available_parallelism()
                .map(|n| n.get())
                .unwrap_or(1)
        });
        let shards = sweep.shards.unwrap_or(1).max(1);
        let width = if shards > 1 {
            todo.len() * shards as usize
        } else {
            todo.len()
        };
        let workers = workers
            .or(sweep.workers)
            .unwrap_or(cores)
            .clamp(1, width.max(1));
        let common = CommonArgs {
            cache: cache_abs.clone(),
            threads: Some((cores / workers).max(1)),
            // One budget for the whole sweep, shared by the points running at once.
            max_memory: Some(texsyn::memory::budget() / workers as u64),
        };
        let finished = std::sync::atomic::AtomicUsize::new(0);
        let total = width + if shards > 1 { todo.len() } else { 0 };
        let report = |task: &local::Task, outcome: &Result<(), String>, seconds: f64| {
            let n = finished.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            if quiet {
                return;
            }
            let what = match task.shard {
                Some((i, n)) => format!("shard {i}/{n} of point {}", task.point.index),
                None => format!("point {}", task.point.index),
            };
            match outcome {
                Ok(()) => println!(
                    "[{n}/{total}] {what} ({}): done in {seconds:.2} s",
                    task.point.label()
                ),
                Err(e) => eprintln!("[{n}/{total}] {what} ({}): failed: {e}", task.point.label()),
            }
        };
        for p in &todo {
            dir.clear_reports(p, shards);
        }
        let mut failures = Default::default();
        let mut ready: Vec<&texsyn::ops::sweep::Point> = todo.clone();
        if shards > 1 {
            // The shards of every point first, then each point whose shards all succeeded
            // gathers them.
            let tasks: Vec<local::Task> = todo
                .iter()
                .flat_map(|&point| {
                    (0..shards).map(move |i| local::Task {
                        point,
                        shard: Some((i, shards)),
                    })
                })
                .collect();
            failures = local::run_tasks(&exe, &sweep, &dir, &tasks, workers, &common, &report);
            ready.retain(|p| !failures.contains_key(&p.index));
        }
        let tasks: Vec<local::Task> = ready
            .iter()
            .map(|&point| local::Task { point, shard: None })
            .collect();
        failures.extend(local::run_tasks(
            &exe, &sweep, &dir, &tasks, workers, &common, &report,
        ));
        failures
    };
    let total = todo.len();
    let table = table::Table::collect(&sweep, &dir, &failures);
    std::fs::create_dir_all(&dir.root)
        .with_context(|| format!("creating {}", dir.root.display()))?;
    write_atomic(&dir.root.join("results.csv"), table.to_csv().as_bytes())?;
    write_atomic(&dir.root.join("results.md"), table.to_markdown().as_bytes())?;
    write_atomic(
        &dir.root.join("results.json"),
        serde_json::to_string_pretty(&table)?.as_bytes(),
    )?;
    // The lock pins a whole, successful sweep; after a failure an older one would mislead.
    let lock = SweepLock::of_reports(&sweep, &dir).filter(|_| failures.is_empty());
    if lock.is_none() {
        let _ = std::fs::remove_file(dir.root.join("sweep.lock"));
    }
    if let Some(lock) = &lock {
        write_atomic(
            &dir.root.join("sweep.lock"),
            lock.to_text(&sweep.path).as_bytes(),
        )?;
    }
    let failed: Vec<_> = table.failed().collect();
    if cli.json {
        println!("{}", serde_json::to_string_pretty(&table)?);
    } else if !cli.quiet {
        println!(
            "{} points ({} run now) in {:.2} s; table: {}",
            sweep.points.len(),
            total,
            start.elapsed().as_secs_f64(),
            dir.root.join("results.md").display()
        );
    }
    if !failed.is_empty() {
        for r in &failed {
            eprintln!(
                "point {} failed: {}",
                r.index,
                r.error.as_deref().unwrap_or("no report")
            );
        }
        eprintln!(
            "{} of {} points failed; rerun the sweep to run only those",
            failed.len(),
            sweep.points.len()
        );
        return Ok(1);
    }
    Ok(0)
}

/// `texsyn hashes SWEEP.toml`: every point's lines, computed in this process, as a sweep lock.
fn sweep_hashes(
    path: &Path,
    sets: &[String],
    output: Option<&Path>,
    cache_dir: &Path,
    progress: ProgressMode,
) -> Result<i32> {
    use texsyn::ops::sweep::lock::{PointLock, SweepLock};
    let sweep = Sweep::load(path)?;
    let mut lock = SweepLock::default();
    for p in &sweep.points {
        let point_sets: Vec<String> = p.sets.iter().chain(sets).cloned().collect();
        let (_, result) = run_config(&sweep.base, &point_sets, cache_dir, progress)
            .with_context(|| format!("point {} ({})", p.index, p.label()))?;
        lock.points.push(PointLock {
            index: p.index,
            label: p.label(),
            lock: LockFile::of_reports(&result.reports, &[]),
        });
    }
    let text = lock.to_text(path);
    match output {
        Some(o) => write_atomic(o, text.as_bytes())?,
        None => print!("{text}"),
    }
    Ok(0)
}

/// `texsyn verify SWEEP.toml SWEEP.lock`: every point against its section of the lock.
fn sweep_verify(
    path: &Path,
    lockfile: &Path,
    sets: &[String],
    fresh: bool,
    cache_dir: &Path,
    progress: ProgressMode,
    cli: &Cli,
) -> Result<i32> {
    use texsyn::ops::sweep::lock::SweepLock;
    let sweep = Sweep::load(path)?;
    let lock = SweepLock::read(lockfile)?;
    let temp = fresh.then(|| outputs::TempDir::new("texsyn-verify"));
    let cache = match &temp {
        Some(t) => Cache::open(t.path())?,
        None => Cache::open_existing(cache_dir)?,
    };
    let mut problems = Vec::new();
    let mut damaged = Vec::new();
    let mut artifacts = 0;
    for p in &sweep.points {
        let section = match lock.section(p) {
            Ok(s) => s,
            Err(e) => {
                problems.push(e);
                continue;
            }
        };
        let point_sets: Vec<String> = p.sets.iter().chain(sets).cloned().collect();
        let plan = load_plan(&sweep.base, &point_sets)
            .with_context(|| format!("point {} ({})", p.index, p.label()))?;
        let result = pipeline::run(
            &plan.dag,
            &cache,
            RunOptions {
                progress,
                verify_all: true,
            },
        )?;
        artifacts += result.reports.len();
        for d in section
            .lock
            .compare(&LockFile::of_reports(&result.reports, &[]))
        {
            problems.push(format!("point {} ({}): {d}", p.index, p.label()));
        }
        damaged.extend(result.damaged);
    }
    for extra in lock
        .points
        .iter()
        .filter(|l| !sweep.points.iter().any(|p| p.index == l.index))
    {
        problems.push(format!(
            "point {} ({}) is in the lock file but not in the sweep",
            extra.index, extra.label
        ));
    }
    let code = if !problems.is_empty() {
        VERIFY_MISMATCH
    } else if !damaged.is_empty() {
        VERIFY_DAMAGED
    } else {
        0
    };
    if cli.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({
                "lockfile": lockfile,
                "points": sweep.points.len(),
                "artifacts": artifacts,
                "mismatches": problems,
                "damaged": damaged,
                "exit_code": code,
            }))?
        );
    }
    print_verify_problems(&damaged, &problems, lockfile);
    if problems.is_empty() && !cli.quiet && !cli.json {
        println!(
            "verified: {} points, {artifacts} artifacts match {}",
            sweep.points.len(),
            lockfile.display()
        );
    }
    Ok(code)
}
