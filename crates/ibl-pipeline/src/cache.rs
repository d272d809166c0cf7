//! The content-addressed cache: stage keys, the manifest of what is built, and the object store.
//!
//! A stage's key is the blake3 hash of the tool (its version and the fingerprint of the sources
//! its bake runs, see [`tool_for`]), its kind, its canonical parameters and,
//! for each source it reads in order, the digest of that input's bytes and names (see
//! [`input_digest`]) or the key of the upstream stage. Keys of upstream stages (not the bytes
//! of their outputs) make every key known before anything runs; bakes are deterministic, so a
//! key names its outputs' bytes.
//!
//! Under `OUTPUT/.bake/`:
//! - `manifest.json`: per stage, the key it was built with, what the key was made of (to say
//!   why a stage re-runs), and its outputs with size, mtime and hash (to notice outputs deleted
//!   or edited by hand); and a stamp cache of input hashes (size + mtime → hash), so an unchanged
//!   run re-reads nothing.
//! - `cache/<key>.json` and `objects/<hash>`: the outputs of recent keys of each stage, as hard
//!   links (copies where links are impossible), so deleted outputs and reverted parameters come
//!   back without baking.
//! - `tmp/`: staging for outputs being written (renamed into place only when complete), and
//!   `journal/`: commits in flight, rolled forward by the next run after a kill.
//!
//! Every file here is written by temp + rename.

use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::io::Read;
use std::path::{Path, PathBuf};

pub const MANIFEST_VERSION: u32 = 1;
/// How many keys per stage keep their outputs in the object store.
pub const KEEP_KEYS: usize = 3;

/// Size, modification time and content hash of a file.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct FileStamp {
    pub size: u64,
    pub mtime_ns: u64,
    pub hash: String,
}

/// The `tool` part of every key: the package version and a fingerprint of the workspace
/// sources this build was compiled from (`build.rs`). The version alone stays the same across
/// commits that change what a bake computes; with the fingerprint, results baked by other code
/// are never reused (they are rebuilt once after such a change).
pub fn tool() -> String {
    format!(
        "{}+{}",
        ibl_core::TOOL_VERSION,
        env!("IBL_BUILD_FINGERPRINT")
    )
}

/// Per workspace library crate, the fingerprint of the code its bakes run (that crate and its
/// workspace dependencies, without tests; `build.rs`).
const LIBRARY_FINGERPRINTS: &[(&str, &str)] =
    include!(concat!(env!("OUT_DIR"), "/library_fingerprints.rs"));

/// The `tool` part of the keys of stages whose bake lives in the crate `library`: the package
/// version and that library's fingerprint, so editing tests, the plotting crate or another
/// bake's library leaves these keys alone. An unknown crate falls back to [`tool`].
pub fn tool_for(library: &str) -> String {
    match LIBRARY_FINGERPRINTS
        .iter()
        .find(|(name, _)| *name == library)
    {
        Some((_, fp)) => format!("{}+{}", ibl_core::TOOL_VERSION, fp),
        None => tool(),
    }
}

/// What a stage key is made of.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct KeyParts {
    pub tool: String,
    pub kind: String,
    /// Canonical JSON of the parameters.
    pub params: String,
    /// (name, digest) of each source read, in order: an input's content digest or a stage's key.
    pub reads: Vec<(String, String)>,
}

impl KeyParts {
    /// The key: a hash of everything above, the labels of the sources excluded: renaming a
    /// declared input or a stage does not invalidate what reads it (the names of the files an
    /// input holds are part of its digest).
    pub fn key(&self) -> String {
        let mut h = blake3::Hasher::new();
        for part in ["ibl-bake/key/v1", &self.tool, &self.kind, &self.params] {
            h.update(part.as_bytes());
            h.update(&[0]);
        }
        for (_, digest) in &self.reads {
            h.update(digest.as_bytes());
            h.update(&[0]);
        }
        h.finalize().to_hex().to_string()
    }

    /// Why `self` (the key a stage was built with) differs from `now`, in words.
    pub fn diff(&self, now: &KeyParts) -> String {
        let mut why = Vec::new();
        if self.tool != now.tool {
            why.push(format!("bake tool changed ({} -> {})", self.tool, now.tool));
        }
        if self.kind != now.kind {
            why.push(format!("kind changed ({} -> {})", self.kind, now.kind));
        }
        if self.params != now.params {
            why.push(params_diff(&self.params, &now.params));
        }
        if self.reads.len() != now.reads.len()
            || self.reads.iter().zip(&now.reads).any(|(a, b)| a.0 != b.0)
        {
            if self
                .reads
                .iter()
                .map(|r| &r.1)
                .ne(now.reads.iter().map(|r| &r.1))
            {
                why.push("reads changed".into());
            }
        } else {
            for ((name, a), (_, b)) in self.reads.iter().zip(&now.reads) {
                if a != b {
                    why.push(format!("{name} changed"));
                }
            }
        }
        if why.is_empty() {
            "key changed".into()
        } else {
            why.join("; ")
        }
    }
}

/// "parameters changed: size 64 -> 32, half false -> true".
fn params_diff(old: &str, new: &str) -> String {
    let (Ok(serde_json::Value::Object(a)), Ok(serde_json::Value::Object(b))) = (
        serde_json::from_str::<serde_json::Value>(old),
        serde_json::from_str::<serde_json::Value>(new),
    ) else {
        return "parameters changed".into();
    };
    let mut keys: Vec<&String> = a.keys().chain(b.keys()).collect();
    keys.sort();
    keys.dedup();
    let null = serde_json::Value::Null;
    let changes: Vec<String> = keys
        .into_iter()
        .filter(|k| a.get(*k) != b.get(*k))
        .map(|k| {
            format!(
                "{k} {} -> {}",
                a.get(k).unwrap_or(&null),
                b.get(k).unwrap_or(&null)
            )
        })
        .collect();
    format!("parameters changed: {}", changes.join(", "))
}

/// An output of a built stage.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct OutputRecord {
    /// Relative to the stage's folder.
    pub rel: String,
    #[serde(flatten)]
    pub stamp: FileStamp,
}

/// True for a digest as the runner writes them (keys, object hashes): 64 lowercase hex
/// characters. Anything else read back from `.bake/` is damaged, and is never made into a path.
pub fn is_digest(s: &str) -> bool {
    s.len() == 64
        && s.bytes()
            .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
}

/// True for a relative path of plain names only (no `..`, `.`, root or drive): joined to a
/// folder, it stays inside it.
pub fn is_inside_rel(rel: &str) -> bool {
    let p = Path::new(rel);
    !rel.is_empty()
        && p.components()
            .all(|c| matches!(c, std::path::Component::Normal(_)))
}

impl OutputRecord {
    /// Its path stays in the stage folder and its hash is a digest.
    pub fn is_sound(&self) -> bool {
        is_inside_rel(&self.rel) && is_digest(&self.stamp.hash)
    }
}

/// A built stage.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StageRecord {
    pub key: String,
    pub parts: KeyParts,
    /// The stage's folder, relative to the output folder.
    pub dir: String,
    pub outputs: Vec<OutputRecord>,
    pub seconds: f64,
    /// Earlier keys whose outputs the object store keeps (most recent first).
    #[serde(default)]
    pub history: Vec<String>,
    /// For a stage baked item by item (see [`crate::kinds::Item`]): each item's key and
    /// outputs, by item name.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub items: BTreeMap<String, ItemRecord>,
}

/// An item of a stage baked item by item.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ItemRecord {
    /// Its own key: the stage's tool, kind and parameters, its name and its inputs' digest.
    pub key: String,
    /// The digest of the files it reads (to say which changed).
    pub inputs: String,
    /// Its outputs, relative to the stage's folder.
    pub outputs: Vec<String>,
    /// Earlier keys of this item whose outputs the object store keeps (most recent first).
    #[serde(default)]
    pub history: Vec<String>,
}

impl ItemRecord {
    /// Its keys are digests and its outputs stay in the stage folder.
    pub fn is_sound(&self) -> bool {
        is_digest(&self.key)
            && self.history.iter().all(|k| is_digest(k))
            && self.outputs.iter().all(|o| is_inside_rel(o))
    }
}

/// The key of an item of a stage whose key is made of `parts`: everything of the stage's key
/// but its reads, the item's name and the digest of the files it reads.
pub fn item_key(parts: &KeyParts, name: &str, inputs_digest: &str) -> String {
    let mut h = blake3::Hasher::new();
    for part in [
        "ibl-bake/item/v1",
        &parts.tool,
        &parts.kind,
        &parts.params,
        name,
        inputs_digest,
    ] {
        h.update(part.as_bytes());
        h.update(&[0]);
    }
    h.finalize().to_hex().to_string()
}

impl StageRecord {
    /// Its keys are digests and its paths stay in the output folder, out of `.bake/`: a record
    /// read back that is not sound is damaged and is dropped (its stage is rebuilt).
    pub fn is_sound(&self) -> bool {
        is_digest(&self.key)
            && self.history.iter().all(|k| is_digest(k))
            && is_inside_rel(&self.dir)
            && !Path::new(&self.dir).starts_with(".bake")
            && self.outputs.iter().all(OutputRecord::is_sound)
            && self.items.values().all(ItemRecord::is_sound)
    }
}

/// What is built under an output folder.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Manifest {
    pub version: u32,
    pub stages: BTreeMap<String, StageRecord>,
    /// Input hash cache: path → stamp.
    #[serde(default)]
    pub files: BTreeMap<String, FileStamp>,
}

impl Manifest {
    /// Records `record` for stage `id`: keeps the previous key in its history (for the object
    /// store) and removes the previous outputs (in `output`) that the new ones do not replace.
    pub fn apply(&mut self, output: &Path, id: &str, mut record: StageRecord) {
        // Only the outputs of a sound record are removed: they lie in the output folder.
        if let Some(old) = self.stages.remove(id).filter(StageRecord::is_sound) {
            let new_files: std::collections::HashSet<PathBuf> = record
                .outputs
                .iter()
                .map(|o| output.join(&record.dir).join(&o.rel))
                .collect();
            for o in &old.outputs {
                let p = output.join(&old.dir).join(&o.rel);
                // Only a file that still holds the bytes recorded, reached without a symlink
                // out of the output folder: anything else is not ours to remove.
                let ours = matches_stamp(&p, &o.stamp, false)
                    && ibl_core::ownership::check_inside(&p, output).is_ok();
                if ours && !new_files.contains(&p) {
                    let _ = std::fs::remove_file(&p);
                    crate::paths::remove_empty_parents(&p, output);
                }
            }
            record.history = recent_keys(old.key, old.history, &record.key);
            for (name, item) in &mut record.items {
                if let Some(was) = old.items.get(name) {
                    item.history = recent_keys(was.key.clone(), was.history.clone(), &item.key);
                }
            }
        }
        self.stages.insert(id.to_string(), record);
    }
}

/// The keys the object store keeps besides `now`: the previous key `old`, then its
/// `history`, at most [`KEEP_KEYS`]` - 1`, `now` left out.
fn recent_keys(old: String, history: Vec<String>, now: &str) -> Vec<String> {
    let mut keys = vec![];
    if old != now {
        keys.push(old);
    }
    keys.extend(history.into_iter().filter(|k| k != now));
    keys.truncate(KEEP_KEYS - 1);
    keys
}

/// Paths under `OUTPUT/.bake/`.
#[derive(Clone, Debug)]
pub struct CacheDir {
    pub output: PathBuf,
    pub root: PathBuf,
}

impl CacheDir {
    pub fn new(output: &Path) -> Self {
        CacheDir {
            output: output.to_path_buf(),
            root: output.join(".bake"),
        }
    }
    pub fn manifest_path(&self) -> PathBuf {
        self.root.join("manifest.json")
    }
    /// The cache entry file of `key`; `None` unless `key` is a digest.
    pub fn entry_path(&self, key: &str) -> Option<PathBuf> {
        is_digest(key).then(|| self.root.join("cache").join(format!("{key}.json")))
    }
    /// The object file of `hash`; `None` unless `hash` is a digest.
    pub fn object_path(&self, hash: &str) -> Option<PathBuf> {
        is_digest(hash).then(|| self.root.join("objects").join(&hash[..2]).join(hash))
    }
    pub fn tmp(&self) -> PathBuf {
        self.root.join("tmp")
    }
    pub fn journal(&self) -> PathBuf {
        self.root.join("journal")
    }
    pub fn lock_path(&self) -> PathBuf {
        self.root.join("lock")
    }

    /// The manifest, or an empty one when there is none (or it is from another version).
    /// Damaged records (see [`StageRecord::is_sound`]) are left out.
    pub fn load_manifest(&self) -> Result<Manifest> {
        let path = self.manifest_path();
        match std::fs::read(&path) {
            Ok(bytes) => match serde_json::from_slice::<Manifest>(&bytes) {
                Ok(mut m) if m.version == MANIFEST_VERSION => {
                    m.stages.retain(|_, r| r.is_sound());
                    Ok(m)
                }
                // An unreadable or older manifest only costs a rebuild.
                _ => Ok(Manifest {
                    version: MANIFEST_VERSION,
                    ..Default::default()
                }),
            },
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(Manifest {
                version: MANIFEST_VERSION,
                ..Default::default()
            }),
            Err(e) => Err(Error::io(path, e)),
        }
    }

    /// Writes the manifest (atomically, synced), unless the file already holds exactly that.
    pub fn save_manifest(&self, m: &Manifest) -> Result<()> {
        let bytes = serde_json::to_vec_pretty(m).expect("manifest serialises");
        if std::fs::read(self.manifest_path()).is_ok_and(|old| old == bytes) {
            return Ok(());
        }
        write_atomic(&self.manifest_path(), &bytes)
    }

    /// The cache entry of `key`, if present, sound (digests, paths inside the stage folder)
    /// and all its objects exist; a damaged entry is a miss.
    pub fn entry(&self, key: &str) -> Option<CacheEntry> {
        let bytes = std::fs::read(self.entry_path(key)?).ok()?;
        let e: CacheEntry = serde_json::from_slice(&bytes).ok()?;
        e.files
            .iter()
            .all(|f| f.is_sound() && self.object_path(&f.stamp.hash).is_some_and(|o| o.is_file()))
            .then_some(e)
    }

    /// Keeps `files` (already in place in `dir`) as the outputs of `key`.
    pub fn put(&self, key: &str, dir: &Path, files: &[OutputRecord]) -> Result<()> {
        let damaged = |what: String| {
            Error::io(
                &self.root,
                std::io::Error::new(std::io::ErrorKind::InvalidData, what),
            )
        };
        let entry_path = self
            .entry_path(key)
            .ok_or_else(|| damaged(format!("'{key}' is not a cache key")))?;
        for f in files {
            let Some(obj) = self.object_path(&f.stamp.hash).filter(|_| f.is_sound()) else {
                return Err(damaged(format!(
                    "output record '{}' ({}) is damaged",
                    f.rel, f.stamp.hash
                )));
            };
            if obj.is_file() {
                continue;
            }
            let parent = obj.parent().expect("object has a folder");
            std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
            let tmp = temp_beside(&obj);
            let src = dir.join(&f.rel);
            if std::fs::hard_link(&src, &tmp).is_err() {
                std::fs::copy(&src, &tmp).map_err(|e| Error::io(&src, e))?;
            }
            std::fs::rename(&tmp, &obj).map_err(|e| Error::io(&obj, e))?;
        }
        let entry = CacheEntry {
            files: files.to_vec(),
        };
        write_atomic(
            &entry_path,
            &serde_json::to_vec_pretty(&entry).expect("entry serialises"),
        )
    }

    /// Links (or copies) the objects of `entry` into `staging`, checking their hashes first.
    /// Returns (staged file, path relative to the stage folder); `None` if an object or the
    /// entry is damaged.
    pub fn stage_entry(
        &self,
        entry: &CacheEntry,
        staging: &Path,
    ) -> Result<Option<Vec<(PathBuf, String)>>> {
        std::fs::create_dir_all(staging).map_err(|e| Error::io(staging, e))?;
        let mut out = Vec::new();
        for (n, f) in entry.files.iter().enumerate() {
            let Some(obj) = self.object_path(&f.stamp.hash).filter(|_| f.is_sound()) else {
                return Ok(None);
            };
            match hash_file(&obj) {
                Ok((h, size)) if h == f.stamp.hash && size == f.stamp.size => {}
                _ => {
                    let _ = std::fs::remove_file(&obj);
                    return Ok(None);
                }
            }
            let staged = staging.join(format!("{n}"));
            if std::fs::hard_link(&obj, &staged).is_err() {
                std::fs::copy(&obj, &staged).map_err(|e| Error::io(&obj, e))?;
            }
            out.push((staged, f.rel.clone()));
        }
        Ok(Some(out))
    }

    /// Removes cache entries no stage of `m` keeps, and objects no kept entry uses.
    pub fn collect_garbage(&self, m: &Manifest) -> Result<()> {
        let kept: std::collections::HashSet<String> = m
            .stages
            .values()
            .flat_map(|r| {
                std::iter::once(r.key.clone())
                    .chain(r.history.iter().cloned())
                    .chain(r.items.values().flat_map(|i| {
                        std::iter::once(i.key.clone()).chain(i.history.iter().cloned())
                    }))
            })
            .collect();
        let mut live = std::collections::HashSet::new();
        let cache = self.root.join("cache");
        if let Ok(rd) = std::fs::read_dir(&cache) {
            for e in rd.flatten() {
                let name = e.file_name().to_string_lossy().into_owned();
                let key = name.trim_end_matches(".json");
                if kept.contains(key) {
                    if let Ok(bytes) = std::fs::read(e.path()) {
                        if let Ok(entry) = serde_json::from_slice::<CacheEntry>(&bytes) {
                            live.extend(entry.files.into_iter().map(|f| f.stamp.hash));
                        }
                    }
                } else {
                    let _ = std::fs::remove_file(e.path());
                }
            }
        }
        if let Ok(rd) = std::fs::read_dir(self.root.join("objects")) {
            for sub in rd.flatten() {
                if let Ok(objs) = std::fs::read_dir(sub.path()) {
                    for o in objs.flatten() {
                        if !live.contains(&*o.file_name().to_string_lossy()) {
                            let _ = std::fs::remove_file(o.path());
                        }
                    }
                }
                let _ = std::fs::remove_dir(sub.path());
            }
        }
        Ok(())
    }
}

/// The outputs of one key, relative to the stage's folder.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CacheEntry {
    pub files: Vec<OutputRecord>,
}

/// Whether the file at `path` still holds the bytes `stamp` records: size and modification
/// time first (cheap), the hash when they moved (or when `rehash`). A symlink never matches.
pub(crate) fn matches_stamp(path: &Path, stamp: &FileStamp, rehash: bool) -> bool {
    let Ok(md) = std::fs::symlink_metadata(path) else {
        return false;
    };
    if !md.is_file() || md.len() != stamp.size {
        return false;
    }
    if !rehash && mtime_ns(&md) == stamp.mtime_ns {
        return true;
    }
    hash_file(path).is_ok_and(|(h, _)| h == stamp.hash)
}

/// Modification time in nanoseconds since the epoch (0 when unknown).
pub fn mtime_ns(md: &std::fs::Metadata) -> u64 {
    md.modified()
        .ok()
        .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}

/// blake3 of a file's bytes (hex) and its size.
pub fn hash_file(path: &Path) -> std::io::Result<(String, u64)> {
    let mut f = std::fs::File::open(path)?;
    let mut h = blake3::Hasher::new();
    let mut buf = vec![0u8; 1 << 16];
    let mut size = 0u64;
    loop {
        let n = f.read(&mut buf)?;
        if n == 0 {
            break;
        }
        size += n as u64;
        h.update(&buf[..n]);
    }
    Ok((h.finalize().to_hex().to_string(), size))
}

pub fn hash_bytes(bytes: &[u8]) -> String {
    blake3::hash(bytes).to_hex().to_string()
}

/// Hashes files, trusting a stamp whose size and mtime are unchanged.
pub struct Hasher<'a> {
    pub known: &'a BTreeMap<String, FileStamp>,
    pub fresh: BTreeMap<String, FileStamp>,
}

impl<'a> Hasher<'a> {
    pub fn new(known: &'a BTreeMap<String, FileStamp>) -> Self {
        Hasher {
            known,
            fresh: BTreeMap::new(),
        }
    }

    pub fn stamp(&mut self, path: &Path) -> std::io::Result<FileStamp> {
        let key = crate::paths::absolute(path).to_string_lossy().into_owned();
        if let Some(s) = self.fresh.get(&key) {
            return Ok(s.clone());
        }
        let md = std::fs::metadata(path)?;
        let (size, mtime) = (md.len(), mtime_ns(&md));
        let stamp = match self.known.get(&key) {
            Some(s) if s.size == size && s.mtime_ns == mtime && mtime != 0 => s.clone(),
            _ => {
                let (hash, size) = hash_file(path)?;
                FileStamp {
                    size,
                    mtime_ns: mtime,
                    hash,
                }
            }
        };
        self.fresh.insert(key, stamp.clone());
        Ok(stamp)
    }
}

/// The digest of an input from its files' hashes and the names a bake sees: a file's own name
/// (not its folder), a folder's own name and its files' paths inside it, a glob's matches'
/// paths from `base`. Names matter: bakes choose decoders by extension, read folder layouts, and
/// name outputs after their inputs (quat-map writes `<input name>/...` when it reads several);
/// so renaming an input re-runs what reads it, while the same bytes under the same name found
/// somewhere else still hit the cache.
pub fn input_digest(kind: &str, base: &Path, files: &[(PathBuf, String)]) -> String {
    let mut h = blake3::Hasher::new();
    h.update(kind.as_bytes());
    h.update(&[0]);
    if kind == "folder" {
        let own = base.file_name().unwrap_or_default().to_string_lossy();
        h.update(own.as_bytes());
        h.update(&[0]);
    }
    for (path, hash) in files {
        let name = if kind == "file" {
            path.file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default()
        } else {
            path.strip_prefix(base)
                .unwrap_or(path)
                .to_string_lossy()
                .into_owned()
        };
        h.update(name.as_bytes());
        h.update(&[0]);
        h.update(hash.as_bytes());
        h.update(&[0]);
    }
    h.finalize().to_hex().to_string()
}

/// A hidden temporary name beside `target`, unique to this process and call.
pub fn temp_beside(target: &Path) -> PathBuf {
    use std::sync::atomic::{AtomicU64, Ordering};
    static N: AtomicU64 = AtomicU64::new(0);
    let name = target
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    target.with_file_name(format!(
        ".{name}.tmp-{}-{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    ))
}

/// Writes a runner file (manifest, entry, journal) by temp + rename, creating its folder.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    ibl_core::io::write_atomic(path, bytes).map_err(Error::from)
}

/// A record of stage folder `dir` with `files` (rel, bytes), for tests.
#[cfg(test)]
pub(crate) fn test_record(dir: &str, files: &[(&str, &[u8])]) -> StageRecord {
    StageRecord {
        key: hash_bytes(dir.as_bytes()),
        parts: KeyParts {
            tool: "t".into(),
            kind: "k".into(),
            params: "{}".into(),
            reads: vec![],
        },
        dir: dir.into(),
        outputs: files
            .iter()
            .map(|(rel, b)| OutputRecord {
                rel: rel.to_string(),
                stamp: FileStamp {
                    size: b.len() as u64,
                    mtime_ns: 0,
                    hash: hash_bytes(b),
                },
            })
            .collect(),
        seconds: 0.0,
        history: vec![],
        items: BTreeMap::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parts() -> KeyParts {
        KeyParts {
            tool: "0.1.0".into(),
            kind: "prefilter".into(),
            params: r#"{"samples":64,"size":32}"#.into(),
            reads: vec![("upstream 'cube'".into(), "k1".into())],
        }
    }

    #[test]
    fn keys_change_with_every_part_but_not_with_names() {
        let base = parts();
        let k = base.key();
        assert_eq!(k, parts().key());
        let mut p = parts();
        p.tool = "0.2.0".into();
        assert_ne!(p.key(), k);
        let mut p = parts();
        p.params = r#"{"samples":64,"size":16}"#.into();
        assert_ne!(p.key(), k);
        assert_eq!(base.diff(&p), "parameters changed: size 32 -> 16");
        let mut p = parts();
        p.reads[0].1 = "k2".into();
        assert_ne!(p.key(), k);
        assert_eq!(base.diff(&p), "upstream 'cube' changed");
        let mut p = parts();
        p.reads[0].0 = "renamed".into();
        assert_eq!(p.key(), k);
        let mut p = parts();
        p.reads.push(("x".into(), "d".into()));
        assert_ne!(p.key(), k);
    }

    #[test]
    fn the_tool_part_of_keys_is_the_version_and_the_build_fingerprint() {
        let t = tool();
        let (version, fp) = t.split_once('+').unwrap();
        assert_eq!(version, ibl_core::TOOL_VERSION);
        assert!(
            fp.len() == 16 && fp.bytes().all(|b| b.is_ascii_hexdigit()),
            "{t}"
        );
    }

    mod fingerprint {
        include!(concat!(env!("CARGO_MANIFEST_DIR"), "/build/fingerprint.rs"));
    }

    #[test]
    fn the_build_fingerprint_follows_contents_and_names_not_mtimes_or_places() {
        let write = |root: &Path, rel: &str, text: &str| {
            let p = root.join(rel);
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(p, text).unwrap();
        };
        let make = |root: &Path, files: &[(&str, &str)]| {
            for (rel, text) in files {
                write(root, rel, text);
            }
            fingerprint::fingerprint(root).unwrap()
        };
        let files = [
            ("Cargo.toml", "[workspace]"),
            ("Cargo.lock", "lock"),
            ("crates/a/Cargo.toml", "[package] a"),
            ("crates/a/src/lib.rs", "pub fn f() -> f32 { 1.0 }"),
            ("crates/a/src/deep/m.rs", "// m"),
            ("crates/b/Cargo.toml", "[package] b"),
            ("crates/b/src/main.rs", "fn main() {}"),
            ("crates/b/tests/t.rs", "// not part of a bake"),
        ];
        let (d1, d2) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
        let (fp, watch) = make(d1.path(), &files);
        assert!(watch.contains(&d1.path().join("crates/a/src")), "{watch:?}");
        // Another place, files created in another order, later mtimes: the same fingerprint.
        let mut reversed = files;
        reversed.reverse();
        assert_eq!(make(d2.path(), &reversed).0, fp);
        // Code changes change it; files outside src do not.
        write(d2.path(), "crates/a/src/deep/m.rs", "// m2");
        let changed = fingerprint::fingerprint(d2.path()).unwrap().0;
        assert_ne!(changed, fp);
        write(d2.path(), "crates/a/src/deep/m.rs", "// m");
        write(d2.path(), "crates/b/tests/t.rs", "// edited");
        assert_eq!(fingerprint::fingerprint(d2.path()).unwrap().0, fp);
        // So do renames, new files and dependency versions.
        std::fs::rename(
            d2.path().join("crates/a/src/deep/m.rs"),
            d2.path().join("crates/a/src/deep/n.rs"),
        )
        .unwrap();
        assert_ne!(fingerprint::fingerprint(d2.path()).unwrap().0, fp);
        write(d1.path(), "crates/b/src/extra.rs", "");
        assert_ne!(fingerprint::fingerprint(d1.path()).unwrap().0, fp);
        std::fs::remove_file(d1.path().join("crates/b/src/extra.rs")).unwrap();
        assert_eq!(fingerprint::fingerprint(d1.path()).unwrap().0, fp);
        write(d1.path(), "Cargo.lock", "lock2");
        assert_ne!(fingerprint::fingerprint(d1.path()).unwrap().0, fp);
    }

    #[test]
    fn a_library_fingerprint_follows_only_the_code_its_bakes_run() {
        let root = tempfile::tempdir().unwrap();
        let root = root.path();
        let write = |rel: &str, text: &str| {
            let p = root.join(rel);
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(p, text).unwrap();
        };
        let lib = |body: &str, test: &str| {
            format!(
                "//! A crate.\n\npub fn f() -> f32 {{\n    {body}\n}}\n\n#[cfg(test)]\n\
                 fn helper() -> f32 {{ 2.0 }}\n\n#[cfg(test)]\nmod tests {{\n    \
                 #[test]\n    fn t() {{\n        assert_eq!(helper(), {test}.0);\n    }}\n}}\n"
            )
        };
        write("Cargo.toml", "[workspace]\nmembers = [\"crates/*\"]\n");
        write("Cargo.lock", "lock");
        let toml = |name: &str, deps: &str| {
            format!("[package]\nname = \"{name}\"\n\n[dependencies]\n{deps}\n[dev-dependencies]\nibl-plot.workspace = true\n")
        };
        write(
            "crates/core/Cargo.toml",
            &toml("ibl-core", "glam = \"0.30\""),
        );
        write("crates/core/src/lib.rs", &lib("1.0", "3"));
        write(
            "crates/pre/Cargo.toml",
            &toml("ibl-prefilter", "ibl-core.workspace = true"),
        );
        write("crates/pre/src/lib.rs", &lib("2.0", "3"));
        write("crates/pre/tests/e2e.rs", "// end to end");
        write(
            "crates/lut/Cargo.toml",
            &toml("ibl-lut", "ibl-core = { path = \"../core\" }"),
        );
        write("crates/lut/src/lib.rs", &lib("3.0", "3"));
        write("crates/plot/Cargo.toml", &toml("ibl-plot", ""));
        write("crates/plot/src/lib.rs", &lib("4.0", "3"));
        let keys = || {
            ["ibl-prefilter", "ibl-lut"].map(|l| {
                fingerprint::library_fingerprint(root, l)
                    .unwrap()
                    .expect("a workspace crate")
            })
        };
        let [pre, lut] = keys();
        assert_ne!(pre, lut);
        let all = fingerprint::library_fingerprints(root).unwrap();
        assert_eq!(all.len(), 4);
        assert!(
            all.contains(&("ibl-lut".to_string(), lut.clone())),
            "{all:?}"
        );
        assert_eq!(
            fingerprint::library_fingerprint(root, "nope").unwrap(),
            None
        );
        // Test-only code, tests/, the plotting crate (a dev-dependency only): no change.
        write("crates/pre/src/lib.rs", &lib("2.0", "4"));
        write("crates/core/src/lib.rs", &lib("1.0", "5"));
        write("crates/pre/tests/e2e.rs", "// edited");
        write("crates/plot/src/lib.rs", &lib("4.5", "3"));
        assert_eq!(keys(), [pre.clone(), lut.clone()]);
        let helper = lib("1.0", "5").replace("{ 2.0 }", "{ 2.5 }");
        write("crates/core/src/lib.rs", &helper);
        assert_eq!(keys(), [pre.clone(), lut.clone()]);
        // A library's own code changes its key, not another library's.
        write("crates/pre/src/lib.rs", &lib("2.5", "4"));
        let [pre2, lut2] = keys();
        assert_ne!(pre2, pre);
        assert_eq!(lut2, lut);
        // A shared dependency's code changes both.
        write("crates/core/src/lib.rs", &lib("1.5", "5"));
        let [pre3, lut3] = keys();
        assert!(pre3 != pre2 && lut3 != lut2);
    }

    #[test]
    fn every_kind_keys_on_its_own_library_fingerprint() {
        for kind in crate::kinds::all() {
            let t = tool_for(kind.library());
            assert!(
                LIBRARY_FINGERPRINTS
                    .iter()
                    .any(|(name, fp)| *name == kind.library() && t.ends_with(fp)),
                "{}: no fingerprint for '{}'",
                kind.name(),
                kind.library()
            );
        }
    }

    #[test]
    fn stamps_skip_rehashing_until_the_file_changes() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("a.bin");
        std::fs::write(&f, b"hello").unwrap();
        let empty = BTreeMap::new();
        let mut h = Hasher::new(&empty);
        let s = h.stamp(&f).unwrap();
        assert_eq!(s.hash, hash_bytes(b"hello"));
        // A stamp with the same size and mtime is trusted (even if we lie about the hash).
        let mut known = h.fresh.clone();
        known.values_mut().for_each(|v| v.hash = "trusted".into());
        assert_eq!(Hasher::new(&known).stamp(&f).unwrap().hash, "trusted");
        std::fs::write(&f, b"hellO!").unwrap();
        assert_eq!(
            Hasher::new(&known).stamp(&f).unwrap().hash,
            hash_bytes(b"hellO!")
        );
    }

    #[test]
    fn input_digests_see_the_names_bakes_see_but_not_where_the_input_lies() {
        let base = Path::new("/b");
        let f = |n: &str| (PathBuf::from(n), "h".to_string());
        // The same bytes under the same name elsewhere: a cache hit.
        assert_eq!(
            input_digest("file", base, &[f("/b/x.exr")]),
            input_digest("file", base, &[f("/c/x.exr")])
        );
        // Renamed: quat-map names the output folder after it, so the key changes.
        assert_ne!(
            input_digest("file", base, &[f("/b/x.png")]),
            input_digest("file", base, &[f("/b/y.png")])
        );
        assert_ne!(
            input_digest("file", base, &[f("/b/x.exr")]),
            input_digest("file", base, &[f("/b/x.hdr")])
        );
        assert_ne!(
            input_digest("folder", base, &[f("/b/m/normal.png")]),
            input_digest("folder", base, &[f("/b/n/normal.png")])
        );
        // A folder's own name counts too; where it lies does not.
        let folder = |b: &str, n: &str| input_digest("folder", Path::new(b), &[f(n)]);
        assert_ne!(
            folder("/w/mats", "/w/mats/a/normal.png"),
            folder("/w/other", "/w/other/a/normal.png")
        );
        assert_eq!(
            folder("/w/mats", "/w/mats/a/normal.png"),
            folder("/v/mats", "/v/mats/a/normal.png")
        );
    }

    #[test]
    fn store_keeps_and_restores_outputs_and_collects_garbage() {
        let dir = tempfile::tempdir().unwrap();
        let cache = CacheDir::new(dir.path());
        let k1 = hash_bytes(b"k1");
        let stage = dir.path().join("s");
        std::fs::create_dir_all(&stage).unwrap();
        std::fs::write(stage.join("a.exr"), b"AAA").unwrap();
        let rec = OutputRecord {
            rel: "a.exr".into(),
            stamp: FileStamp {
                size: 3,
                mtime_ns: 0,
                hash: hash_bytes(b"AAA"),
            },
        };
        cache.put(&k1, &stage, std::slice::from_ref(&rec)).unwrap();
        std::fs::remove_file(stage.join("a.exr")).unwrap();
        let entry = cache.entry(&k1).unwrap();
        let staged = cache
            .stage_entry(&entry, &dir.path().join("tmp"))
            .unwrap()
            .unwrap();
        assert_eq!(std::fs::read(&staged[0].0).unwrap(), b"AAA");
        assert_eq!(staged[0].1, "a.exr");
        // A damaged object is refused (and dropped).
        std::fs::remove_file(&staged[0].0).unwrap();
        std::fs::write(cache.object_path(&rec.stamp.hash).unwrap(), b"AAB").unwrap();
        assert!(cache
            .stage_entry(&entry, &dir.path().join("tmp2"))
            .unwrap()
            .is_none());
        assert!(cache.entry(&k1).is_none());
        // Entries of keys no stage keeps go, with their objects.
        cache.put(&k1, &dir.path().join("tmp"), &[]).unwrap();
        cache.collect_garbage(&Manifest::default()).unwrap();
        assert!(!cache.entry_path(&k1).unwrap().exists());
    }

    #[test]
    fn a_damaged_cache_entry_is_a_miss_and_touches_nothing_outside_the_cache() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        let cache = CacheDir::new(&out);
        // A file outside the output folder that a crafted hash would name.
        let victim = dir.path().join("victim");
        std::fs::write(&victim, b"keep me").unwrap();
        let key = hash_bytes(b"key");
        let write_entry = |hash: &str, rel: &str| {
            let json = format!(
                r#"{{"files": [{{"rel": "{rel}", "size": 7, "mtime_ns": 0, "hash": "{hash}"}}]}}"#
            );
            let path = cache.root.join("cache").join(format!("{key}.json"));
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            std::fs::write(path, json).unwrap();
        };
        let good = hash_bytes(b"keep me");
        for (hash, rel) in [
            ("", "a.exr"),
            ("a", "a.exr"),
            ("é", "a.exr"),
            ("../../victim", "a.exr"),
            (good.to_uppercase().as_str(), "a.exr"),
            (good.as_str(), "../../victim"),
            (good.as_str(), "/etc/passwd"),
        ] {
            write_entry(hash, rel);
            assert!(cache.entry(&key).is_none(), "{hash:?} {rel:?}");
            let entry: CacheEntry = serde_json::from_slice(
                &std::fs::read(cache.root.join("cache").join(format!("{key}.json"))).unwrap(),
            )
            .unwrap();
            assert!(
                cache.stage_entry(&entry, &cache.tmp()).unwrap().is_none(),
                "{hash:?} {rel:?}"
            );
            assert!(cache.put(&key, &out, &entry.files).is_err());
            assert_eq!(std::fs::read(&victim).unwrap(), b"keep me");
        }
        // Keys that are not digests name no file.
        assert!(cache.entry("../../victim").is_none());
        assert!(cache.entry_path("../x").is_none() && cache.object_path("ab").is_none());
        assert!(cache.put("../../victim", &out, &[]).is_err());
    }

    #[test]
    fn damaged_manifest_records_are_dropped_on_load() {
        let dir = tempfile::tempdir().unwrap();
        let cache = CacheDir::new(dir.path());
        let record = |key: &str, dir: &str, rel: &str| StageRecord {
            key: key.into(),
            parts: parts(),
            dir: dir.into(),
            outputs: vec![OutputRecord {
                rel: rel.into(),
                stamp: FileStamp {
                    size: 1,
                    mtime_ns: 0,
                    hash: hash_bytes(b"x"),
                },
            }],
            seconds: 0.0,
            history: vec![],
            items: BTreeMap::new(),
        };
        let k = hash_bytes(b"k");
        let mut m = Manifest {
            version: MANIFEST_VERSION,
            ..Default::default()
        };
        for (id, r) in [
            ("ok", record(&k, "a/b", "c/d.exr")),
            ("bad-key", record("k", "a", "d.exr")),
            ("bad-dir", record(&k, "../x", "d.exr")),
            ("in-cache", record(&k, ".bake/objects", "d.exr")),
            ("bad-rel", record(&k, "a", "../../d.exr")),
            ("abs-rel", record(&k, "a", "/d.exr")),
        ] {
            m.stages.insert(id.into(), r);
        }
        let mut bad_history = record(&k, "h", "d.exr");
        bad_history.history = vec!["../k".into()];
        m.stages.insert("bad-history".into(), bad_history);
        std::fs::create_dir_all(&cache.root).unwrap();
        std::fs::write(cache.manifest_path(), serde_json::to_vec(&m).unwrap()).unwrap();
        let loaded = cache.load_manifest().unwrap();
        assert_eq!(loaded.stages.keys().collect::<Vec<_>>(), ["ok"]);
    }

    #[test]
    fn a_new_record_removes_the_outputs_the_old_one_had_and_keeps_history() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path();
        std::fs::create_dir_all(out.join("s")).unwrap();
        for f in ["m0.exr", "m1.exr", "m2.exr"] {
            std::fs::write(out.join("s").join(f), f).unwrap();
        }
        let mut m = Manifest::default();
        m.apply(
            out,
            "s",
            test_record(
                "s",
                &[
                    ("m0.exr", b"m0.exr"),
                    ("m1.exr", b"m1.exr"),
                    ("m2.exr", b"m2.exr"),
                ],
            ),
        );
        let mut shorter = test_record("s", &[("m0.exr", b"m0.exr"), ("m1.exr", b"m1.exr")]);
        shorter.key = "other".into();
        m.apply(out, "s", shorter);
        assert!(out.join("s/m1.exr").exists() && !out.join("s/m2.exr").exists());
        assert_eq!(m.stages["s"].history, vec![hash_bytes(b"s")]);
    }

    #[test]
    fn item_keys_keep_their_history_and_their_objects_survive_garbage_collection() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path();
        let cache = CacheDir::new(out);
        std::fs::create_dir_all(out.join("s/a")).unwrap();
        std::fs::write(out.join("s/a/q.png"), b"one").unwrap();
        let item = |key: &str| ItemRecord {
            key: key.into(),
            inputs: hash_bytes(b"inputs"),
            outputs: vec!["a/q.png".into()],
            history: vec![],
        };
        let (k1, k2) = (hash_bytes(b"k1"), hash_bytes(b"k2"));
        let mut rec = test_record("s", &[("a/q.png", b"one")]);
        rec.items.insert("a/q.png".into(), item(&k1));
        cache.put(&k1, &out.join("s"), &rec.outputs).unwrap();
        let mut m = Manifest::default();
        m.apply(out, "s", rec.clone());
        // The item is rebuilt with another key: the first one stays in its history, and the
        // object store keeps its outputs (a revert restores them without baking).
        rec.items.insert("a/q.png".into(), item(&k2));
        m.apply(out, "s", rec.clone());
        assert_eq!(m.stages["s"].items["a/q.png"].history, vec![k1.clone()]);
        cache.collect_garbage(&m).unwrap();
        assert!(
            cache.entry(&k1).is_some(),
            "the earlier item key was collected"
        );
        // Dropped from the record altogether (the item was removed): collected.
        rec.items.clear();
        m.apply(out, "s", rec);
        cache.collect_garbage(&m).unwrap();
        assert!(cache.entry(&k1).is_none());
        // A damaged item record makes its stage's record unsound.
        let mut bad = test_record("s", &[]);
        bad.items.insert(
            "x".into(),
            ItemRecord {
                outputs: vec!["../x".into()],
                ..item(&k2)
            },
        );
        assert!(!bad.is_sound());
    }
}
