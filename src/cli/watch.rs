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
use texsyn::report::{Reload, message_page};

#[derive(clap::Args)]
pub struct WatchArgs {
    config: PathBuf,
    /// Override a config value, as `run --set`.
    #[arg(long = "set", value_name = "STAGE.KEY=VALUE")]
    sets: Vec<String>,
    /// Output folder. Default: out/<config name>.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Serve the report on http://127.0.0.1:PORT/ (0: a free port, printed); the page reloads
    /// itself after each rerun.
    #[arg(long, value_name = "PORT")]
    serve: Option<u16>,
}

/// How long to wait after an event for the others of the same save.
const SETTLE: Duration = Duration::from_millis(150);

enum Message {
    Changed(Vec<PathBuf>),
    /// The watcher lost events (a queue overflow): anything may have changed.
    Rescan,
    Stop,
}

/// What the server hands out: the current page and its version.
struct Served {
    version: u64,
    html: std::sync::Arc<str>,
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
            eprintln!("stopping once the run in hand is done (Ctrl-C again stops at once)");
            let _ = tx.send(Message::Stop);
        })
        .context("installing the Ctrl-C handler")?;
    }
    let mut watcher = folder_watcher(tx.clone())?;
    let placeholder = message_page(
        "texsyn watch",
        &format!(
            "<p>Running {} for the first time; this page reloads when it is done.</p>",
            texsyn::report::escape(&args.config.display().to_string())
        ),
        Some(Reload {
            url: "/version",
            version: 0,
        }),
    );
    let served = Arc::new(Mutex::new(Served {
        version: 0,
        html: placeholder.into(),
    }));
    if let Some(port) = args.serve {
        let addr = serve(port, served.clone())?;
        println!("serving the report on http://{addr}/");
    }
    let config =
        std::path::absolute(&args.config).with_context(|| format!("{}", args.config.display()))?;
    let mut watched = Watched::default();
    let mut inputs: Vec<PathBuf> = Vec::new();
    let mut version = 0u64;
    loop {
        version += 1;
        // Watch before running, so a save during the run (a cold one can take minutes) is
        // seen. A config that does not load keeps the last inputs that did.
        if let Ok(plan) = super::load_plan(&args.config, &args.sets) {
            inputs = plan.dag.files.iter().map(|f| f.path.clone()).collect();
        }
        watched.update(&mut watcher, &config, inputs.clone());
        rerun(args, g, &served, version);
        if stopping.load(Ordering::SeqCst) {
            break;
        }
        if !g.quiet {
            println!(
                "watching {} and {} input file(s); Ctrl-C stops",
                args.config.display(),
                watched.files.len().saturating_sub(1)
            );
        }
        if !wait_for_change(&rx, &watched) {
            break;
        }
    }
    if !g.quiet {
        println!("stopped; the cache and {} are whole", out_name(args));
    }
    Ok(0)
}

fn out_name(args: &WatchArgs) -> String {
    match &args.out {
        Some(o) => o.display().to_string(),
        None => "the outputs".into(),
    }
}

/// One run: says what reran, rewrites the report and hands the served page its new version
/// (a page saying what failed, when the run did).
fn rerun(args: &WatchArgs, g: &Globals, served: &Mutex<Served>, version: u64) {
    let reload = Reload {
        url: "/version",
        version,
    };
    let serve = |html: String| {
        if args.serve.is_some() {
            let mut s = served.lock().unwrap_or_else(|e| e.into_inner());
            *s = Served {
                version,
                html: html.into(),
            };
        }
    };
    let outcome = match run_and_write(&args.config, &args.sets, args.out.as_deref(), false, g) {
        Ok(o) => o,
        Err(e) => {
            eprintln!("error: {e:#}");
            serve(message_page(
                "texsyn watch: the run failed",
                &format!(
                    "<p>Run {version} of {} failed; this page reloads after the next one.</p>\
                     <pre>{}</pre>",
                    texsyn::report::escape(&args.config.display().to_string()),
                    texsyn::report::escape(&format!("{e:#}"))
                ),
                Some(reload),
            ));
            return;
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
    if !g.quiet {
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
    }
    // One page: on disk without the reload hook (a file:// page cannot poll), served with it.
    match run_html(&args.config, &args.sets, &outcome, Some(reload)) {
        Ok(html) => {
            let file = outcome.out_dir.join("report.html");
            let on_disk = html.replacen(&reload_meta(version), "", 1);
            if let Err(e) = super::write_atomic(&file, on_disk.as_bytes()) {
                eprintln!("error: writing the report {}: {e:#}", file.display());
            }
            serve(html);
        }
        Err(e) => eprintln!("error: making the report: {e:#}"),
    }
}

/// The reload hook the served page carries (as `texsyn::report` writes it).
fn reload_meta(version: u64) -> String {
    format!("<meta name=\"texsyn-reload\" content=\"/version\" data-version=\"{version}\">\n")
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
        let Ok(event) = res else {
            let _ = tx.send(Message::Rescan);
            return;
        };
        if event.need_rescan() {
            let _ = tx.send(Message::Rescan);
            return;
        }
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

/// How long the events of one save may keep arriving before the rerun starts anyway.
const SETTLE_AT_MOST: Duration = Duration::from_secs(2);

/// Waits for a change to a watched file, then for the events of the same save to settle
/// (events of other files in the watched folders neither start nor prolong the wait).
/// False when asked to stop.
fn wait_for_change(rx: &Receiver<Message>, watched: &Watched) -> bool {
    let relevant = |m: &Message| match m {
        Message::Changed(paths) => paths.iter().any(|p| watched.concerns(p)),
        Message::Rescan => true,
        Message::Stop => false,
    };
    loop {
        match rx.recv() {
            Ok(Message::Stop) | Err(_) => return false,
            Ok(m) if relevant(&m) => break,
            Ok(_) => {}
        }
    }
    let deadline = std::time::Instant::now() + SETTLE_AT_MOST;
    let mut quiet_until = std::time::Instant::now() + SETTLE;
    loop {
        let now = std::time::Instant::now();
        let until = quiet_until.min(deadline);
        if now >= until {
            return true;
        }
        match rx.recv_timeout(until - now) {
            Ok(Message::Stop) => return false,
            Ok(m) if relevant(&m) => quiet_until = std::time::Instant::now() + SETTLE,
            Ok(_) => {}
            Err(RecvTimeoutError::Timeout) => return true,
            Err(RecvTimeoutError::Disconnected) => return false,
        }
    }
}

/// Serves the current page at `/` and its version at `/version` on 127.0.0.1:`port` (0: a
/// free port); the address it listens on. Requests naming another host are refused, so a web
/// page elsewhere cannot read the report through a name that resolves to 127.0.0.1.
fn serve(port: u16, served: Arc<Mutex<Served>>) -> Result<std::net::SocketAddr> {
    let server = tiny_http::Server::http(("127.0.0.1", port))
        .map_err(|e| anyhow::anyhow!("serving on 127.0.0.1:{port}: {e}"))?;
    let addr = server
        .server_addr()
        .to_ip()
        .context("the report server has no IP address")?;
    let hosts = [
        format!("127.0.0.1:{}", addr.port()),
        format!("localhost:{}", addr.port()),
    ];
    std::thread::Builder::new()
        .name("texsyn-serve".into())
        .spawn(move || {
            for request in server.incoming_requests() {
                let host_ok = request
                    .headers()
                    .iter()
                    .find(|h| h.field.equiv("Host"))
                    .is_some_and(|h| hosts.iter().any(|ok| h.value.as_str() == ok));
                let (body, kind, status): (std::sync::Arc<str>, &str, u16) = if !host_ok {
                    ("forbidden host".into(), "text/plain", 403)
                } else {
                    let s = served.lock().unwrap_or_else(|e| e.into_inner());
                    match request.url() {
                        "/" | "/report.html" => (s.html.clone(), "text/html; charset=utf-8", 200),
                        "/version" => (s.version.to_string().into(), "text/plain", 200),
                        _ => ("not found".into(), "text/plain", 404),
                    }
                };
                let response = tiny_http::Response::from_data(body.as_bytes().to_vec())
                    .with_status_code(status)
                    .with_header(header("Content-Type", kind))
                    .with_header(header("Cache-Control", "no-store"));
                let _ = request.respond(response);
            }
        })
        .context("starting the report server")?;
    Ok(addr)
}

fn header(name: &str, value: &str) -> tiny_http::Header {
    tiny_http::Header::from_bytes(name.as_bytes(), value.as_bytes()).expect("a valid ASCII header")
}
