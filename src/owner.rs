//! Who made a temporary file, and whether that process is provably gone.
//!
//! Every temporary name texsyn writes (cache objects being stored, output staging folders and
//! journals, files written beside their destination, temporary folders) carries an owner tag
//! `HOST_BOOT_NS_PID`: the host name (letters and digits only, at most 32), the first 16 hex
//! digits of the kernel's boot id (`/proc/sys/kernel/random/boot_id`), the inode number of
//! the process's PID namespace (`/proc/self/ns/pid`) and the process id in that namespace.
//!
//! A leftover is removed at once only when its owner is provably dead: same host name, same
//! boot, same PID namespace as the process looking, that namespace is the one `/proc` shows,
//! and `/proc/PID` is missing. Anything else (another host sharing the folder over NFS, another
//! container or `unshare`d namespace, another boot, a name without a tag, a system without
//! `/proc`) is left alone until it is older than [`STALE_AGE`] by its modification time.

use std::path::Path;
use std::sync::OnceLock;
use std::time::{Duration, SystemTime};

/// How old a temporary of an owner whose death cannot be proven must be before it is removed.
pub const STALE_AGE: Duration = Duration::from_secs(24 * 3600);

/// The process that made a temporary name.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Owner {
    host: String,
    boot: String,
    ns: String,
    pid: u32,
}

/// What is known of an owner.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Liveness {
    /// The process asking.
    ThisProcess,
    /// In this namespace of this boot and `/proc/PID` exists (or its id was reused).
    Alive,
    /// In this namespace of this boot and `/proc/PID` is missing.
    Dead,
    /// Another host, boot or namespace, or nothing could be learnt: only age may tell.
    Unknown,
}

/// What this process's tag is made of, learnt once.
struct Here {
    host: String,
    boot: String,
    ns: String,
    /// Whether `/proc` shows this process's own PID namespace (`/proc/self` is our pid).
    proc_is_ours: bool,
}

fn here() -> &'static Here {
    static HERE: OnceLock<Here> = OnceLock::new();
    HERE.get_or_init(|| {
        let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
            .ok()
            .or_else(|| std::env::var("HOSTNAME").ok())
            .unwrap_or_default();
        let mut host: String = host
            .chars()
            .filter(|c| c.is_ascii_alphanumeric())
            .take(32)
            .collect();
        if host.is_empty() {
            host = "host".into();
        }
        let boot: String = std::fs::read_to_string("/proc/sys/kernel/random/boot_id")
            .unwrap_or_default()
            .chars()
            .filter(|c| c.is_ascii_hexdigit())
            .take(16)
            .collect();
        let ns: String = std::fs::read_link("/proc/self/ns/pid")
            .ok()
            .map(|l| {
                l.to_string_lossy()
                    .chars()
                    .filter(|c| c.is_ascii_digit())
                    .collect()
            })
            .unwrap_or_default();
        let proc_is_ours = std::fs::read_link("/proc/self")
            .is_ok_and(|l| l.to_string_lossy() == std::process::id().to_string());
        Here {
            host,
            boot: if boot.len() == 16 { boot } else { "0".into() },
            ns: if ns.is_empty() { "0".into() } else { ns },
            proc_is_ours,
        }
    })
}

impl Owner {
    /// This process.
    pub fn this() -> Owner {
        Owner::with_pid(std::process::id())
    }

    /// Process `pid` of this host, boot and PID namespace.
    pub fn with_pid(pid: u32) -> Owner {
        let h = here();
        Owner {
            host: h.host.clone(),
            boot: h.boot.clone(),
            ns: h.ns.clone(),
            pid,
        }
    }

    /// The tag written into temporary names: `HOST_BOOT_NS_PID`, letters, digits and `_` only.
    pub fn tag(&self) -> String {
        format!("{}_{}_{}_{}", self.host, self.boot, self.ns, self.pid)
    }

    /// This process's tag.
    pub fn this_tag() -> String {
        Owner::this().tag()
    }

    /// Reads a tag as [`Owner::tag`] writes it; anything else is `None`.
    pub fn parse(tag: &str) -> Option<Owner> {
        let mut parts = tag.split('_');
        let host = parts.next()?;
        let boot = parts.next()?;
        let ns = parts.next()?;
        let pid = parts.next()?;
        let alnum = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_alphanumeric());
        let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
        if parts.next().is_some() || !alnum(host) || !alnum(boot) || !digits(ns) || !digits(pid) {
            return None;
        }
        Some(Owner {
            host: host.into(),
            boot: boot.into(),
            ns: ns.into(),
            pid: pid.parse().ok()?,
        })
    }

    pub fn pid(&self) -> u32 {
        self.pid
    }

    /// What can be proven about this owner from here.
    pub fn liveness(&self) -> Liveness {
        let h = here();
        let comparable = h.boot != "0" && h.ns != "0" && h.proc_is_ours;
        if !comparable || self.host != h.host || self.boot != h.boot || self.ns != h.ns {
            return Liveness::Unknown;
        }
        if self.pid == std::process::id() {
            Liveness::ThisProcess
        } else if Path::new("/proc").join(self.pid.to_string()).exists() {
            Liveness::Alive
        } else {
            Liveness::Dead
        }
    }
}

/// Whether the leftover at `path` whose name carries `owner` (`None`: no tag could be read)
/// may be removed: its owner is provably dead, or it is older than [`STALE_AGE`]. With
/// `own_is_dead`, what carries this process's own tag counts as dead too (for callers whose
/// writers are serialized and clean up before returning).
pub fn may_remove(owner: Option<&Owner>, path: &Path, own_is_dead: bool) -> bool {
    match owner.map(Owner::liveness) {
        Some(Liveness::Dead) => return true,
        Some(Liveness::ThisProcess) => return own_is_dead,
        // A live owner may be in the middle of a long run (a `verify --fresh` cache is
        // written once and then only read): its files stay, whatever their age. A reused
        // pid leaves a leftover behind, which is the safer mistake.
        Some(Liveness::Alive) => return false,
        _ => {}
    }
    older_than(path, STALE_AGE)
}

/// The temporary name of a file written beside its destination `dest` and renamed over it:
/// `.NAME.tmp-OWNER` in the same folder.
pub fn temporary_beside(dest: &Path) -> std::path::PathBuf {
    let name = dest
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    dest.with_file_name(format!(".{name}.tmp-{}", Owner::this_tag()))
}

/// Removes the temporaries that killed writers of `dest` left beside it (`.NAME.tmp-OWNER`,
/// see [`temporary_beside`]) when [`may_remove`] allows; never a live or unknown writer's
/// young one. Best effort: what cannot be removed stays.
pub fn remove_stale_beside(dest: &Path) {
    let Some(name) = dest.file_name().map(|n| n.to_string_lossy().into_owned()) else {
        return;
    };
    let dir = match dest.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let prefix = format!(".{name}.tmp-");
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let file = e.file_name();
        let Some(rest) = file.to_str().and_then(|f| f.strip_prefix(&prefix)) else {
            continue;
        };
        let path = e.path();
        if std::fs::symlink_metadata(&path).is_ok_and(|m| m.is_file())
            && may_remove(Owner::parse(rest).as_ref(), &path, false)
        {
            let _ = std::fs::remove_file(&path);
        }
    }
}

/// Whether `path`'s modification time is more than `age` ago (false if it cannot be read).
pub fn older_than(path: &Path, age: Duration) -> bool {
    std::fs::symlink_metadata(path)
        .and_then(|m| m.modified())
        .is_ok_and(|t| {
            SystemTime::now()
                .duration_since(t)
                .is_ok_and(|elapsed| elapsed > age)
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tags_round_trip_and_say_who() {
        let me = Owner::this();
        assert_eq!(Owner::parse(&me.tag()), Some(me.clone()));
        assert!(!me.tag().contains(['-', '.', '/']));
        for bad in ["", "123", "a_b_c", "a_b_c_d", "a_b_1_2_3", "a-x_b_1_2"] {
            assert_eq!(Owner::parse(bad), None, "{bad:?}");
        }
        if cfg!(target_os = "linux") {
            assert_eq!(me.liveness(), Liveness::ThisProcess);
            let mut other_ns = me.clone();
            other_ns.ns = "1".into();
            other_ns.pid = u32::MAX;
            assert_eq!(other_ns.liveness(), Liveness::Unknown);
            let mut other_host = Owner::with_pid(u32::MAX);
            assert_eq!(other_host.liveness(), Liveness::Dead);
            other_host.host = "elsewhere".into();
            assert_eq!(other_host.liveness(), Liveness::Unknown);
        }
    }
}
