//! The record of the source files a bake read, so that an open of a baked map reads the
//! layers' pages and the binary decal and tree lists instead of decoding the map's image and
//! text files.
//!
//! `pages/sources.toml` names each source file (a raster layer's image, the decal list, the tree
//! list) with its
//! length, a content key ([`super::SourceKey`] of its bytes) and the key of what was baked from
//! it. It is a pure function of the sources, so bakes on any machines write the same bytes.
//!
//! Checking a file's content costs a read of the whole file (a quarter of a second for the
//! heights of a 32 km map), so `MAP/.pages_checked`, kept on this machine only, remembers each
//! file's length and modification time when its content last matched the record: later opens
//! only look at the files' metadata. A file copied (new time, same bytes) is read once and
//! remembered again; a file changed after the bake is decoded as without pages (logged).

use super::{PageError, SourceKey};
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::UNIX_EPOCH;

const FORMAT: &str = "tvs-page-sources";
const VERSION: u32 = 1;
/// The record's file name in the pages folder.
pub const RECORD_FILE: &str = "sources.toml";
/// The machine-local memory of checked files, in the map folder.
pub const CHECKED_FILE: &str = ".pages_checked";

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RecordFile {
    format: String,
    version: u32,
    #[serde(default)]
    file: Vec<Entry>,
}

/// One source file of a bake.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Entry {
    /// The file's name in the map folder.
    name: String,
    bytes: u64,
    /// Hexadecimal [`SourceKey`] of the file's bytes ([`content_key`]).
    content_key: String,
    /// Hexadecimal key of what was baked from it (the page file's or the decal list's key).
    baked_key: String,
}

/// A file's length and modification time (nanoseconds since 1970), as `.pages_checked` keeps it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Stamp {
    bytes: u64,
    modified_ns: u128,
}

fn stamp(path: &Path) -> Option<Stamp> {
    let meta = std::fs::metadata(path).ok()?;
    let modified_ns = meta
        .modified()
        .ok()?
        .duration_since(UNIX_EPOCH)
        .ok()?
        .as_nanos();
    Some(Stamp {
        bytes: meta.len(),
        modified_ns,
    })
}

/// The [`SourceKey`] of the bytes of the file at `path`, read in blocks of 1 MiB.
pub fn content_key(path: &Path) -> std::io::Result<u64> {
    use std::io::Read;
    let mut file = std::fs::File::open(path)?;
    let mut key = SourceKey::new(0xF11E_0000);
    let mut block = vec![0u8; 1 << 20];
    loop {
        let n = file.read(&mut block)?;
        if n == 0 {
            return Ok(key.finish());
        }
        key.update(&block[..n]);
    }
}

fn hex(v: u64) -> String {
    format!("{v:016x}")
}

/// The record of a baked map's source files, read for an open.
#[derive(Debug)]
pub struct Sources {
    map_dir: PathBuf,
    entries: Vec<Entry>,
    /// `.pages_checked`: (name, stamp, content key) of files whose content matched.
    checked: Vec<(String, Stamp, String)>,
    checked_changed: bool,
}

impl Sources {
    /// Writes `pages/sources.toml` for the files `baked` (name in `map_dir`, key of what was
    /// baked from it), reading each file for its content key, and remembers them as checked.
    /// Files not in `map_dir` (pages baked into another folder) are left out: an open decodes
    /// them.
    pub fn write(map_dir: &Path, baked: &[(String, u64)]) -> Result<(), PageError> {
        let path = record_path(map_dir);
        let mut entries = Vec::with_capacity(baked.len());
        let mut checked = Vec::with_capacity(baked.len());
        for (name, key) in baked {
            let source = map_dir.join(name);
            if !source.is_file() {
                continue;
            }
            let io = |source_err| PageError::Io {
                path: source.clone(),
                action: "read the source file of",
                source: source_err,
            };
            let before = stamp(&source);
            let content = hex(content_key(&source).map_err(io)?);
            if let Some(s) = before.filter(|&s| Some(s) == stamp(&source)) {
                checked.push((name.clone(), s, content.clone()));
            }
            entries.push(Entry {
                name: name.clone(),
                bytes: before.map_or(0, |s| s.bytes),
                content_key: content,
                baked_key: hex(*key),
            });
        }
        let text = toml::to_string(&RecordFile {
            format: FORMAT.into(),
            version: VERSION,
            file: entries,
        })
        .map_err(|e| PageError::Request {
            path: path.clone(),
            problem: e.to_string(),
        })?;
        let partial = super::fresh_partial_path(&path)?;
        let io = |action, source| PageError::Io {
            path: path.clone(),
            action,
            source,
        };
        std::fs::write(&partial, text).map_err(|e| io("write", e))?;
        std::fs::rename(&partial, &path).map_err(|e| io("move into place", e))?;
        Sources {
            map_dir: map_dir.to_path_buf(),
            entries: Vec::new(),
            checked,
            checked_changed: true,
        }
        .save_checked();
        Ok(())
    }

    /// The record of the map in `map_dir`; `None` when the map has none (not baked) or it
    /// cannot be read (logged: the map is then read from its own files).
    pub fn read(map_dir: &Path) -> Option<Self> {
        let path = record_path(map_dir);
        let text = std::fs::read_to_string(&path).ok()?;
        let record: RecordFile = match toml::from_str(&text) {
            Ok(r) => r,
            Err(e) => {
                log::warn!(
                    "{}: not read ({e}); the map's own files are read",
                    path.display()
                );
                return None;
            }
        };
        if record.format != FORMAT || record.version != VERSION {
            log::warn!(
                "{}: format {} version {} is not {FORMAT} version {VERSION}; the map's own files are read (run `worldgen bake` again)",
                path.display(),
                record.format,
                record.version
            );
            return None;
        }
        Some(Self {
            map_dir: map_dir.to_path_buf(),
            entries: record.file,
            checked: read_checked(&map_dir.join(CHECKED_FILE)),
            checked_changed: false,
        })
    }

    /// The key of what was baked from the file `name` when the file still holds the bytes it
    /// held at the bake (its length and time as last checked here, else its content read and
    /// compared); `None`, logged, when it changed or is not in the record.
    pub fn baked_key(&mut self, name: &str) -> Option<u64> {
        let entry = self.entries.iter().find(|e| e.name == name)?.clone();
        let path = self.map_dir.join(name);
        let now = stamp(&path)?;
        if now.bytes != entry.bytes {
            log::warn!(
                "{}: changed since the bake ({} bytes, baked from {}); decoded instead of its pages (run `worldgen bake` again)",
                path.display(),
                now.bytes,
                entry.bytes
            );
            return None;
        }
        let remembered = self
            .checked
            .iter()
            .any(|(n, s, k)| n == name && *s == now && *k == entry.content_key);
        if !remembered {
            let content = content_key(&path).ok().map(hex);
            if content.as_deref() != Some(entry.content_key.as_str()) {
                log::warn!(
                    "{}: its content changed since the bake; decoded instead of its pages (run `worldgen bake` again)",
                    path.display()
                );
                return None;
            }
            self.checked.retain(|(n, _, _)| n != name);
            self.checked
                .push((name.to_string(), now, entry.content_key.clone()));
            self.checked_changed = true;
        }
        u64::from_str_radix(&entry.baked_key, 16).ok()
    }

    /// Writes `.pages_checked` when a file was checked anew (best effort: a map folder that
    /// cannot be written is checked again next time).
    pub fn save_checked(&self) {
        if !self.checked_changed {
            return;
        }
        let mut text = String::new();
        for (n, s, k) in &self.checked {
            let _ = writeln!(text, "{} {} {k} {n}", s.bytes, s.modified_ns);
        }
        let path = self.map_dir.join(CHECKED_FILE);
        if let Err(e) = std::fs::write(&path, text) {
            log::debug!("{}: not written: {e}", path.display());
        }
    }
}

/// `pages/sources.toml` of the map in `map_dir`.
pub fn record_path(map_dir: &Path) -> PathBuf {
    super::bake::pages_dir(map_dir).join(RECORD_FILE)
}

/// Lines `bytes modified_ns content_key name`; lines that do not parse are skipped.
fn read_checked(path: &Path) -> Vec<(String, Stamp, String)> {
    let Ok(text) = std::fs::read_to_string(path) else {
        return Vec::new();
    };
    text.lines()
        .filter_map(|line| {
            let mut parts = line.splitn(4, ' ');
            let bytes = parts.next()?.parse().ok()?;
            let modified_ns = parts.next()?.parse().ok()?;
            let key = parts.next()?.to_string();
            let name = parts.next()?.to_string();
            Some((name, Stamp { bytes, modified_ns }, key))
        })
        .collect()
}
