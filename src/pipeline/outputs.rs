//! Writes exported file bundles into the run's output directory.
//!
//! Only files whose bytes differ from what is on disk are written, each through a temporary
//! file and a rename, so a failed or interrupted run leaves earlier outputs whole.

use crate::artifact::Artifact;
use crate::artifact::ContentHash;
use crate::artifact::{Bundle, Format};
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    #[error("output {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("exported bundle is damaged: {0}")]
    Bundle(#[from] crate::artifact::ArtifactError),
}

/// What happened to each file: (path, written?).
pub fn materialize(bundle: &Artifact, dir: &Path) -> Result<Vec<(PathBuf, bool)>, OutputError> {
    let io = |path: &Path| {
        let path = path.to_owned();
        move |source| OutputError::Io { path, source }
    };
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let mut out = Vec::new();
    let bundle = Bundle::view(bundle)?;
    for entry in &bundle.entries {
        let path = dir.join(&entry.name);
        let same = std::fs::read(&path)
            .map(|b| b.len() as u64 == entry.len && ContentHash::of(&b) == entry.hash)
            .unwrap_or(false);
        if !same {
            let bytes = bundle.file(entry)?;
            let tmp = dir.join(format!(".{}.tmp-{}", entry.name, std::process::id()));
            std::fs::write(&tmp, &bytes).map_err(io(&tmp))?;
            std::fs::rename(&tmp, &path).map_err(io(&path))?;
        }
        out.push((path, !same));
    }
    Ok(out)
}
