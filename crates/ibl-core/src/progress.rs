//! A progress sink the traversal reports to; binaries plug a terminal bar into it.

/// Receives units of finished work. Must be cheap and thread-safe: the traversal calls it
/// from worker threads once per row of texels, never per texel.
pub trait Progress: Sync {
    /// Announce the total amount of work of a new phase.
    fn start(&self, _label: &str, _total: u64) {}
    /// `n` more units done.
    fn inc(&self, _n: u64) {}
    /// A phase ended.
    fn finish(&self) {}
}

/// Reports nothing (library default, tests, `--quiet`).
pub struct NoProgress;
impl Progress for NoProgress {}
