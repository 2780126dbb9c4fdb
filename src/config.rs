//! Run configs: a TOML file naming a method, its inputs and per-stage parameters.
//!
//! Paths in a config are relative to the config file's directory. `--set stage.key=value`
//! overrides any value (the value is read as TOML, falling back to a plain string). Unknown
//! keys and out-of-range values are errors that name the key.

use serde::de::DeserializeOwned;
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    Syntax { path: PathBuf, message: String },
    #[error("--set {arg:?}: {message}")]
    Set { arg: String, message: String },
    #[error("{path}: {key}: {message}")]
    Invalid {
        path: PathBuf,
        key: String,
        message: String,
    },
}

/// A loaded config with its overrides applied.
#[derive(Debug, Clone)]
pub struct Config {
    pub path: PathBuf,
    /// The directory relative paths are resolved against.
    pub dir: PathBuf,
    /// The file name without extension: names the default output directory.
    pub stem: String,
    pub table: toml::Table,
}

/// The output folder a run of the file `path` (a config or a sweep) writes without `--out`:
/// `out/<stem>`. A stem that is not one plain folder name (`..` of `...toml`, `.` of
/// `..toml`) would put the outputs outside `out/<stem>`, so it is an error naming the file.
pub fn default_out(path: &Path, stem: &str) -> Result<PathBuf, ConfigError> {
    use std::path::Component;
    let mut parts = Path::new(stem).components();
    match (parts.next(), parts.next()) {
        (Some(Component::Normal(_)), None) => Ok(Path::new("out").join(stem)),
        _ => Err(ConfigError::Invalid {
            path: path.to_owned(),
            key: "file name".into(),
            message: format!(
                "its stem {stem:?} cannot name an output folder (out/{stem} is not a folder \
                 inside out/); rename the file or give --out"
            ),
        }),
    }
}

/// The largest config or sweep file texsyn reads (the shipped ones are a few KiB).
pub const TEXT_FILE_CAP: u64 = 4 << 20;

/// Reads a config or sweep file: a regular file (a FIFO or a device such as `/dev/zero` is
/// refused before it is opened for reading) of at most [`TEXT_FILE_CAP`] bytes of UTF-8.
pub fn read_text_file(path: &Path) -> std::io::Result<String> {
    let bytes = crate::geom::io::read_regular_file_capped(path, TEXT_FILE_CAP)?;
    String::from_utf8(bytes).map_err(|e| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("not UTF-8 text (byte {})", e.utf8_error().valid_up_to()),
        )
    })
}

impl Config {
    pub fn load(path: &Path, sets: &[String]) -> Result<Config, ConfigError> {
        let text = read_text_file(path).map_err(|source| ConfigError::Io {
            path: path.to_owned(),
            source,
        })?;
        Self::from_str(path, &text, sets)
    }

    pub fn from_str(path: &Path, text: &str, sets: &[String]) -> Result<Config, ConfigError> {
        let mut table: toml::Table = toml::from_str(text).map_err(|e| ConfigError::Syntax {
            path: path.to_owned(),
            message: e.to_string().trim_end().to_owned(),
        })?;
        for arg in sets {
            apply_set(&mut table, arg)?;
        }
        let dir = path
            .parent()
            .map(|p| {
                if p.as_os_str().is_empty() {
                    Path::new(".")
                } else {
                    p
                }
            })
            .unwrap_or(Path::new("."))
            .to_owned();
        let stem = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "run".into());
        Ok(Config {
            path: path.to_owned(),
            dir,
            stem,
            table,
        })
    }

    /// The `method` key.
    pub fn method(&self) -> Result<&str, ConfigError> {
        match self.table.get("method") {
            Some(toml::Value::String(s)) => Ok(s),
            Some(_) => Err(self.invalid("method", "must be a string")),
            None => Err(self.invalid(
                "method",
                "missing: say which method to run (e.g. method = \"jump_maps\")",
            )),
        }
    }

    /// Deserializes the whole config into a method's config type, reporting the path of the
    /// offending key on error.
    pub fn parse<T: DeserializeOwned>(&self) -> Result<T, ConfigError> {
        let value = toml::Value::Table(self.table.clone());
        serde_path_to_error::deserialize(value).map_err(|e| {
            let key = e.path().to_string();
            let key = if key == "." {
                "(top level)".to_owned()
            } else {
                key
            };
            // toml appends "in `section`" on a second line; the key path says it already.
            let message = e.into_inner().to_string();
            let first = message.lines().next().unwrap_or_default().to_owned();
            self.invalid(&key, &first)
        })
    }

    pub fn invalid(&self, key: &str, message: &str) -> ConfigError {
        ConfigError::Invalid {
            path: self.path.clone(),
            key: key.to_owned(),
            message: message.to_owned(),
        }
    }

    /// A validator's verdict as an error naming the config file and `key`, with the
    /// validator's message kept word for word, e.g. `config.check("synthesize",
    /// params.validate())?` gives `demo.toml: synthesize: synth2d: continuation must be in …`.
    pub fn check<E: std::fmt::Display>(
        &self,
        key: &str,
        verdict: Result<(), E>,
    ) -> Result<(), ConfigError> {
        verdict.map_err(|e| self.invalid(key, &e.to_string()))
    }

    /// A typed parameter error as an error under the key it names. An `Invalid` error's
    /// message completes a sentence that starts with its key, so the key is not repeated.
    pub fn param(&self, e: crate::check::ParamError) -> ConfigError {
        match e {
            crate::check::ParamError::Invalid { key, message } => self.invalid(&key, &message),
            e => self.invalid(e.key(), &e.to_string()),
        }
    }

    /// Whether the config (with its overrides) gives `table.key`, rather than leaving it to
    /// its default: for parameters that a method derives from another when left out.
    pub fn gives(&self, table: &str, key: &str) -> bool {
        self.table.get(table).is_some_and(|t| t.get(key).is_some())
    }

    /// Resolves a path from the config against the config's directory.
    pub fn resolve(&self, p: &Path) -> PathBuf {
        if p.is_absolute() {
            p.to_owned()
        } else {
            self.dir.join(p)
        }
    }
}

fn apply_set(table: &mut toml::Table, arg: &str) -> Result<(), ConfigError> {
    let err = |message: &str| ConfigError::Set {
        arg: arg.to_owned(),
        message: message.to_owned(),
    };
    let (key, raw) = arg
        .split_once('=')
        .ok_or_else(|| err("expected KEY=VALUE, e.g. synthesize.seed=2"))?;
    let parts: Vec<&str> = key.trim().split('.').collect();
    if parts.iter().any(|p| p.is_empty()) {
        return Err(err("the key has an empty part"));
    }
    let value = parse_value(raw.trim());
    let mut t = table;
    for p in &parts[..parts.len() - 1] {
        let entry = t
            .entry(p.to_string())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        t = match entry {
            toml::Value::Table(inner) => inner,
            _ => return Err(err(&format!("`{p}` is not a table"))),
        };
    }
    t.insert(parts[parts.len() - 1].to_string(), value);
    Ok(())
}

fn parse_value(raw: &str) -> toml::Value {
    let doc = format!("v = {raw}");
    match toml::from_str::<toml::Table>(&doc) {
        Ok(mut t) => t
            .remove("v")
            .unwrap_or_else(|| toml::Value::String(raw.into())),
        Err(_) => toml::Value::String(raw.into()),
    }
}

/// Range check used by validators (the core's): the error names the key, the range and the
/// value. [`Config::check`] turns it into a [`ConfigError`] that keeps its text.
pub use crate::check::{ParamError, check_range};

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(serde::Deserialize, Debug)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Demo {
        method: String,
        synthesize: Synth,
    }
    #[derive(serde::Deserialize, Debug)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Synth {
        seed: u64,
        #[serde(default)]
        name: String,
    }

    #[test]
    fn set_overrides_and_creates_keys() {
        let c = Config::from_str(
            Path::new("x/demo.toml"),
            "method = \"m\"\n[synthesize]\nseed = 1\n",
            &["synthesize.seed=2".into(), "synthesize.name=abc".into()],
        )
        .unwrap();
        let d: Demo = c.parse().unwrap();
        assert_eq!(d.synthesize.seed, 2);
        assert_eq!(d.synthesize.name, "abc");
        assert_eq!(c.stem, "demo");
        assert_eq!(c.resolve(Path::new("a.png")), Path::new("x/a.png"));
    }

    #[test]
    fn unknown_keys_are_named_with_their_path() {
        // The message of a `demo.toml` holding `text` that loads but is no `Demo`.
        let error = |text: &str| {
            let c = Config::from_str(Path::new("demo.toml"), text, &[]).unwrap();
            c.parse::<Demo>().unwrap_err().to_string()
        };
        let e = error("method = \"m\"\n[synthesize]\nseed = 1\nsede = 3\n");
        assert!(e.starts_with("demo.toml: synthesize"), "{e}");
        assert!(e.contains("sede"), "{e}");
        let e = error("method = \"m\"\n[synthesize]\nseed = -1\n");
        assert!(e.contains("synthesize.seed"), "{e}");
    }

    #[test]
    fn syntax_errors_name_the_file_and_bad_set_args_are_rejected() {
        let e = Config::from_str(Path::new("bad.toml"), "method = \n", &[]).unwrap_err();
        assert!(e.to_string().starts_with("bad.toml:"), "{e}");
        let e = Config::from_str(Path::new("a.toml"), "", &["noequals".into()]).unwrap_err();
        assert!(e.to_string().contains("KEY=VALUE"));
        let e = Config::from_str(Path::new("a.toml"), "x = 1", &["x.y=2".into()]).unwrap_err();
        assert!(e.to_string().contains("not a table"));
    }
}
