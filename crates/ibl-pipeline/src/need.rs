//! Whether a stage is baked, and why: decided by the scene derivation and by the pipeline's
//! outputs (in the graph), shown by `bake plan`.

/// Whether a stage is baked, and why.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Need {
    /// Baked, for this reason ("declared", "read by 'lobby/prefilter'", ...).
    Needed(String),
    /// Not baked, for this reason ("not needed by the scene: ...").
    NotNeeded(String),
}

impl Need {
    /// Whether the stage is baked.
    pub fn is_needed(&self) -> bool {
        matches!(self, Need::Needed(_))
    }

    /// Why it is or is not baked.
    pub fn why(&self) -> &str {
        match self {
            Need::Needed(w) | Need::NotNeeded(w) => w,
        }
    }
}
