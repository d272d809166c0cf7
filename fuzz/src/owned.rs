//! The entry points of the `ownership` and `budget` fuzz targets (issue 24's checks), shared
//! word for word with the regression test `crates/ibl-core/tests/fuzz_owned.rs` (which
//! includes this file by path), so what the fuzzer ran is what the test replays.
//!
//! - `ownership`: an arbitrary `.ibl-outputs.json` record and arbitrary relative paths under a
//!   fixed output folder holding a subfolder, a file, and symlinks leading in and out of it.
//!   Nothing may panic, and whatever `ibl_core::ownership` accepts (inside, ours to replace, ours
//!   to remove, the record's own names included) must lie inside the folder, both as written
//!   and as the system walks the path.
//! - `budget`: an arbitrary file of any image format (the first byte picks the reader) decoded
//!   under a small memory budget. Whatever its header declares, decoding must allocate no more
//!   than the budget plus a small multiple of the file's own size: what the reader computes
//!   from the header and reserves is what its decoder then allocates, or it is an error.
//!   Measured by [`Counting`], the global allocator of the fuzz target and of the test.

use ibl_core::ownership::{self, Record};
use std::alloc::{GlobalAlloc, Layout, System};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::OnceLock;

// ---------------------------------------------------------------------------------------------
// ownership

/// The output folder of the `ownership` target, made once per process: `sub/` with a file,
/// `px.exr` (bytes `ours`), `in -> sub` and `out -> ..` (the folder above) and `up -> /`.
fn ownership_root() -> &'static Path {
    static ROOT: OnceLock<PathBuf> = OnceLock::new();
    ROOT.get_or_init(|| {
        let base = ownership_base();
        let root = base.join("root");
        let _ = std::fs::create_dir_all(root.join("sub"));
        let _ = std::fs::write(root.join("sub/a.exr"), b"a");
        let _ = std::fs::write(root.join("px.exr"), b"ours");
        let _ = std::fs::write(base.join("outside.exr"), b"not ours");
        #[cfg(unix)]
        {
            let _ = std::os::unix::fs::symlink("sub", root.join("in"));
            let _ = std::os::unix::fs::symlink("..", root.join("out"));
            let _ = std::os::unix::fs::symlink("/", root.join("up"));
            let _ = std::os::unix::fs::symlink("../outside.exr", root.join("link.exr"));
        }
        ownership::resolve(&root)
    })
}

/// The folder above [`ownership_root`]'s (it holds `outside.exr`), one per process.
fn ownership_base() -> PathBuf {
    std::env::temp_dir().join(format!("ibl-fuzz-ownership-{}", std::process::id()))
}

/// Removes this process's `ownership` folders (what [`ownership_root`] made), for a test to
/// call when it is done: the fuzzer's own process leaves them to the system's temp cleaning.
pub fn ownership_cleanup() {
    let _ = std::fs::remove_dir_all(ownership_base());
}

/// Splits an `ownership` input: the record's bytes up to the first NUL, then relative paths,
/// one a line.
pub fn ownership_input(data: &[u8]) -> (&[u8], Vec<PathBuf>) {
    let (record, rest) = match data.iter().position(|&b| b == 0) {
        Some(k) => (&data[..k], &data[k + 1..]),
        None => (data, &[][..]),
    };
    let paths = rest
        .split(|&b| b == b'\n')
        .filter(|l| !l.is_empty() && !l.contains(&0))
        .take(64)
        .map(path_of)
        .collect();
    (record, paths)
}

#[cfg(unix)]
fn path_of(bytes: &[u8]) -> PathBuf {
    use std::os::unix::ffi::OsStrExt;
    PathBuf::from(std::ffi::OsStr::from_bytes(bytes))
}

#[cfg(not(unix))]
fn path_of(bytes: &[u8]) -> PathBuf {
    PathBuf::from(String::from_utf8_lossy(bytes).into_owned())
}

/// Where `f` is for the system: its folder canonicalized as `open(2)` walks it (a `..` after a
/// symlink is taken where the link points), the name appended.
fn walked(f: &Path) -> Option<PathBuf> {
    let name = f.file_name()?;
    let parent = f.parent()?;
    // Canonicalize the longest existing prefix of the folder, as given (not normalized).
    let comps: Vec<_> = parent.components().collect();
    for n in (1..=comps.len()).rev() {
        let prefix: PathBuf = comps[..n].iter().collect();
        if let Ok(mut c) = std::fs::canonicalize(&prefix) {
            c.extend(&comps[n..]);
            let mut c = ownership::normalize(&c);
            c.push(name);
            return Some(c);
        }
    }
    None
}

/// `ownership` target (see the module comment).
pub fn ownership(data: &[u8]) {
    let root = ownership_root();
    let (record, paths) = ownership_input(data);
    // The record as the fuzzer wrote it, read as every tool reads it.
    if std::fs::write(root.join(ownership::RECORD), record).is_err() {
        return;
    }
    let rec = Record::load(root);
    let inside = |f: &Path, what: &str| {
        let lexical = ownership::normalize(f);
        assert!(
            lexical.starts_with(root) && lexical != root,
            "{what}: {} is outside {} as written",
            f.display(),
            root.display()
        );
        if let Some(w) = walked(f) {
            assert!(
                w.starts_with(root),
                "{what}: {} leads to {} for the system",
                f.display(),
                w.display()
            );
        }
        let link = std::fs::symlink_metadata(f).is_ok_and(|m| m.file_type().is_symlink());
        assert!(!link, "{what}: {} is a symlink", f.display());
    };
    // What the record names is never ours to remove outside the folder (`../x`, `out/x`).
    for key in rec.files.keys().take(16) {
        let (ours, _) = ownership::split_owned(root, vec![root.join(key)]);
        for o in &ours {
            inside(o, "split_owned of a recorded name");
        }
    }
    for p in paths {
        let f = root.join(&p);
        let _ = ownership::resolve(&f);
        let _ = ownership::check_output_folder(&f, "-o", true);
        if ownership::check_inside(&f, root).is_ok() {
            inside(&f, "check_inside");
        }
        if rec.owns(root, &f) {
            assert!(
                std::fs::symlink_metadata(&f).is_ok_and(|m| m.is_file()),
                "owns a non-file {}",
                f.display()
            );
        }
        if ownership::check_writes(root, std::slice::from_ref(&f), true).is_ok() {
            inside(&f, "check_writes --overwrite");
        }
        if ownership::check_writes(root, std::slice::from_ref(&f), false).is_ok() {
            inside(&f, "check_writes");
            // Refused unless absent or recorded with these very bytes.
            assert!(
                std::fs::symlink_metadata(&f).is_err() || rec.owns(root, &f),
                "would replace {} which is not ours",
                f.display()
            );
        }
        let (ours, _) = ownership::split_owned(root, vec![f.clone()]);
        for o in &ours {
            inside(o, "split_owned");
            assert!(rec.owns(root, o));
        }
    }
}

// ---------------------------------------------------------------------------------------------
// budget

/// Counts the bytes live and their peak since [`Counting::reset`]. Installed as the global
/// allocator by the `budget` fuzz target and by its replay test; elsewhere it is not, and the
/// `budget` entry then checks only that nothing panics.
pub struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);
static INSTALLED: AtomicBool = AtomicBool::new(false);

impl Counting {
    fn add(n: usize) {
        INSTALLED.store(true, Ordering::Relaxed);
        let live = LIVE.fetch_add(n, Ordering::Relaxed) + n;
        PEAK.fetch_max(live, Ordering::Relaxed);
    }
    /// Starts a new peak at the bytes live now; returns them.
    pub fn reset() -> usize {
        let live = LIVE.load(Ordering::Relaxed);
        PEAK.store(live, Ordering::Relaxed);
        live
    }
    /// The peak of live bytes since [`Counting::reset`], if this allocator is installed.
    pub fn peak() -> Option<usize> {
        INSTALLED
            .load(Ordering::Relaxed)
            .then(|| PEAK.load(Ordering::Relaxed))
    }
}

// SAFETY: every call is forwarded to the system allocator unchanged; only counters are kept.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            Counting::add(layout.size());
        }
        p
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc_zeroed(layout) };
        if !p.is_null() {
            Counting::add(layout.size());
        }
        p
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) };
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
            Counting::add(new_size);
        }
        p
    }
}

/// The budget the `budget` target decodes under.
pub const BUDGET: u64 = 16 << 20;

/// What decoding may allocate beyond the budget: the file's bytes a few times over (copies,
/// inflated chunks checked against the header) and a fixed allowance for tables and buffers.
pub fn allowance(len: usize) -> usize {
    8 * len + (8 << 20)
}

/// The image targets the first byte of a `budget` input picks from.
pub const BUDGET_FORMATS: [&str; 8] = ["exr", "hdr", "png", "jpeg", "ktx2", "zstd", "dds", "ktx1"];

/// `budget` target (see the module comment).
pub fn budget(data: &[u8]) {
    let Some((&pick, file)) = data.split_first() else {
        return;
    };
    let name = BUDGET_FORMATS[pick as usize % BUDGET_FORMATS.len()];
    ibl_core::io::budget::set_max_memory(BUDGET);
    let base = Counting::reset();
    let result = crate::images::decode_target(name, file);
    if let Some(peak) = Counting::peak() {
        let used = peak.saturating_sub(base);
        assert!(
            used <= BUDGET as usize + allowance(file.len()),
            "{name}: decoding {} bytes allocated {used} bytes under a budget of {BUDGET} ({})",
            file.len(),
            match &result {
                Ok(()) => "decoded".to_string(),
                Err(e) => e.to_string(),
            }
        );
    }
    if let Err(e) = result {
        let e = e.to_string();
        assert!(!e.contains('\n'), "{name}: a message of several lines: {e}");
    }
}
