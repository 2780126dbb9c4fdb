//! `texsyn watch CONFIG`: runs the config, then reruns it whenever the config or an input file
//! it reads changes (the operating system's file events, through the `notify` crate), saying
//! which nodes reran, rewriting the outputs and the report page. With `--serve PORT` the page
//! is also served on 127.0.0.1 and reloads itself after each rerun.
//!
//! Folders are watched rather than files, because editors save by writing a new file and
//! renaming it over the old one; events of other files in those folders are ignored. Events
//! that arrive together (one save is several) make one rerun. A failed run (a config being
//! edited is often invalid for a moment) is reported and watching goes on. Ctrl-C stops at
//! once when idle; during a run it lets the run finish its outputs, then stops (a second
//! Ctrl-C exits at once: the cache and the output folder are crash-safe either way).

use super::Globals;
use super::report::run_html;
use super::run::run_and_write;
use anyhow::{Context, Result};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use texsyn::pipeline::NodeStatus;
use texsyn::report::Reload;

#[derive(clap::Args)]
pub struct WatchArgs {
    config: PathBuf,
    /// Override a config value, as `run --set`.
    #[arg(long = "set", value_name = "STAGE.KEY=VALUE")]
    sets: Vec<String>,
    /// Output folder. Default: out/<config name>.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Serve the report on http://127.0.0.1:PORT/ ; the page reloads itself after each rerun.
    #[arg(long, value_name = "PORT")]
    serve: Option<u16>,
}

/// How long to wait after an event for the others of the same save.
const SETTLE: Duration = Duration::from_millis(150);

enum Message {
    Changed(Vec<PathBuf>),
    Stop,
}

/// What the server hands out: the current page and its version.
#[derive(Default)]
struct Served {
    version: u64,
    html: String,
}

/// `texsyn watch`.
pub fn watch(args: &WatchArgs, g: &Globals) -> Result<i32> {
    let (tx, rx) = std::sync::mpsc::channel::<Message>();
    let stopping = Arc::new(AtomicBool::new(false));
    {
        let (tx, stopping) = (tx.clone(), stopping.clone());
        ctrlc::set_handler(move || {
            if stopping.swap(true, Ordering::SeqCst) {
                std::process::exit(130);
            }
            let _ = tx.send(Message::Stop);
        })
        .context("installing the Ctrl-C handler")?;
    }
    let mut watcher = folder_watcher(tx.clone())?;
    let served = Arc::new(Mutex::new(Served::default()));
    if let Some(port) = args.serve {
        serve(port, served.clone())?;
        println!("serving the report on http://127.0.0.1:{port}/");
    }
    let config =
        std::path::absolute(&args.config).with_context(|| format!("{}", args.config.display()))?;
    let mut watched = Watched::default();
    let mut version = 0u64;
    loop {
        version += 1;
        let inputs = rerun(args, g, &served, version);
        watched.update(&mut watcher, &config, inputs);
        if stopping.load(Ordering::SeqCst) {
            break;
        }
        println!(
            "watching {} and {} input file(s); Ctrl-C stops",
            args.config.display(),
            watched.files.len().saturating_sub(1)
        );
        if !wait_for_change(&rx, &watched) {
            break;
        }
    }
    println!("stopped; the cache and {} are whole", out_name(args));
    Ok(0)
}

fn out_name(args: &WatchArgs) -> String {
    match &args.out {
        Some(o) => o.display().to_string(),
        None => "the outputs".into(),
    }
}

/// One run: says what reran and rewrites the report; the input files it read (none when the
/// config could not be planned).
fn rerun(args: &WatchArgs, g: &Globals, served: &Mutex<Served>, version: u64) -> Vec<PathBuf> {
    let outcome = match run_and_write(&args.config, &args.sets, args.out.as_deref(), false, g) {
        Ok(o) => o,
        Err(e) => {
            eprintln!("error: {e:#}");
            // Keep watching the inputs of the last plan that loaded, if any still do.
            return super::load_plan(&args.config, &args.sets)
                .map(|p| p.dag.files.iter().map(|f| f.path.clone()).collect())
                .unwrap_or_default();
        }
    };
    let ran: Vec<&str> = outcome
        .result
        .reports
        .iter()
        .filter(|r| r.status == NodeStatus::Ran)
        .map(|r| r.node.as_str())
        .collect();
    let written = outcome.written.iter().filter(|w| w.1).count();
    println!(
        "run {version}: {}; outputs in {}: {written} written, {} unchanged ({:.2} s)",
        if ran.is_empty() {
            "nothing reran".to_owned()
        } else {
            format!("reran {}", ran.join(", "))
        },
        outcome.out_dir.display(),
        outcome.written.len() - written,
        outcome.seconds
    );
    let page = run_html(&args.config, &args.sets, &outcome, None).and_then(|html| {
        let file = outcome.out_dir.join("report.html");
        super::write_atomic(&file, html.as_bytes())
    });
    if let Err(e) = page {
        eprintln!("error: writing the report: {e:#}");
    }
    if args.serve.is_some() {
        let reload = Reload {
            url: "/version",
            version,
        };
        match run_html(&args.config, &args.sets, &outcome, Some(reload)) {
            Ok(html) => {
                let mut s = served.lock().unwrap_or_else(|e| e.into_inner());
                *s = Served { version, html };
            }
            Err(e) => eprintln!("error: making the served report: {e:#}"),
        }
    }
    outcome
        .plan
        .dag
        .files
        .iter()
        .map(|f| f.path.clone())
        .collect()
}

/// The files whose changes rerun the config, and the folders watched for them.
#[derive(Default)]
struct Watched {
    files: BTreeSet<PathBuf>,
    folders: BTreeSet<PathBuf>,
}

impl Watched {
    /// Watches `config` and `inputs` (their folders), dropping folders no longer needed.
    fn update(
        &mut self,
        watcher: &mut notify::RecommendedWatcher,
        config: &Path,
        inputs: Vec<PathBuf>,
    ) {
        use notify::Watcher;
        let mut files = BTreeSet::new();
        for f in std::iter::once(config.to_owned()).chain(inputs) {
            if let Some(f) = canonical_in_folder(&f) {
                files.insert(f);
            }
        }
        let folders: BTreeSet<PathBuf> = files
            .iter()
            .filter_map(|f| f.parent().map(Path::to_owned))
            .collect();
        for gone in self.folders.difference(&folders) {
            let _ = watcher.unwatch(gone);
        }
        for new in folders.difference(&self.folders) {
            if let Err(e) = watcher.watch(new, notify::RecursiveMode::NonRecursive) {
                eprintln!("warning: cannot watch {}: {e}", new.display());
            }
        }
        self.files = files;
        self.folders = folders;
    }

    fn concerns(&self, path: &Path) -> bool {
        canonical_in_folder(path).is_some_and(|p| self.files.contains(&p))
    }
}

/// `path` as its canonical folder joined with its file name (the file itself may be
/// missing for a moment while an editor replaces it).
fn canonical_in_folder(path: &Path) -> Option<PathBuf> {
    let abs = std::path::absolute(path).ok()?;
    let folder = abs.parent()?.canonicalize().ok()?;
    Some(folder.join(abs.file_name()?))
}

fn folder_watcher(tx: Sender<Message>) -> Result<notify::RecommendedWatcher> {
    use notify::EventKind;
    use notify::event::{AccessKind, AccessMode};
    notify::recommended_watcher(move |res: notify::Result<notify::Event>| {
        let Ok(event) = res else { return };
        let counts = match event.kind {
            // Opening or reading a file changes nothing; closing one written to does.
            EventKind::Access(AccessKind::Close(AccessMode::Write)) => true,
            EventKind::Access(_) => false,
            _ => true,
        };
        if counts {
            let _ = tx.send(Message::Changed(event.paths));
        }
    })
    .context("starting the file watcher")
}

/// Waits for a change to a watched file, then for the events of the same save to settle.
/// False when asked to stop.
fn wait_for_change(rx: &Receiver<Message>, watched: &Watched) -> bool {
    loop {
        match rx.recv() {
            Ok(Message::Stop) | Err(_) => return false,
            Ok(Message::Changed(paths)) if paths.iter().any(|p| watched.concerns(p)) => break,
            Ok(Message::Changed(_)) => {}
        }
    }
    loop {
        match rx.recv_timeout(SETTLE) {
            Ok(Message::Stop) => return false,
            Ok(Message::Changed(_)) => {}
            Err(RecvTimeoutError::Timeout) => return true,
            Err(RecvTimeoutError::Disconnected) => return false,
        }
    }
}

/// Serves the current page at `/` and its version at `/version` on 127.0.0.1:`port`.
fn serve(port: u16, served: Arc<Mutex<Served>>) -> Result<()> {
    let server = tiny_http::Server::http(("127.0.0.1", port))
        .map_err(|e| anyhow::anyhow!("serving on 127.0.0.1:{port}: {e}"))?;
    std::thread::Builder::new()
        .name("texsyn-serve".into())
        .spawn(move || {
            for request in server.incoming_requests() {
                let (body, kind, status) = {
                    let s = served.lock().unwrap_or_else(|e| e.into_inner());
                    match request.url() {
                        "/" | "/report.html" => (s.html.clone(), "text/html; charset=utf-8", 200),
                        "/version" => (s.version.to_string(), "text/plain", 200),
                        _ => ("not found".to_owned(), "text/plain", 404),
                    }
                };
                let response = tiny_http::Response::from_string(body)
                    .with_status_code(status)
                    .with_header(header("Content-Type", kind))
                    .with_header(header("Cache-Control", "no-store"));
                let _ = request.respond(response);
            }
        })
        .context("starting the report server")?;
    Ok(())
}

fn header(name: &str, value: &str) -> tiny_http::Header {
    tiny_http::Header::from_bytes(name.as_bytes(), value.as_bytes()).expect("a valid ASCII header")
}
