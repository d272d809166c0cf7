//! Entry points of the fuzz targets: one function per input parser, each taking arbitrary
//! bytes and required to return without panicking.

mod images;
pub mod mutate;
mod owned;
#[cfg(feature = "pipeline")]
mod pipeline;

pub use images::{container, exr, hdr, jpeg, png, run_image_target, IMAGE_TARGETS};
pub use owned::{budget, ownership, ownership_cleanup, Counting};
#[cfg(feature = "pipeline")]
pub use pipeline::pipeline;

/// Every target, in the order `scripts/fuzz.sh` runs them.
pub const TARGETS: [&str; 8] = [
    "exr",
    "hdr",
    "png",
    "jpeg",
    "ktx2",
    "pipeline",
    "ownership",
    "budget",
];

/// Runs the target called `name` on `data` (the pipeline target only with that feature).
pub fn run_target(name: &str, data: &[u8]) {
    match name {
        #[cfg(feature = "pipeline")]
        "pipeline" => pipeline(data),
        #[cfg(not(feature = "pipeline"))]
        "pipeline" => {}
        "ownership" => ownership(data),
        "budget" => budget(data),
        _ => run_image_target(name, data),
    }
}

/// Called first by every target. `libfuzzer-sys` installs a panic hook that aborts on *any*
/// panic, even one `ibl_core::io` catches and turns into an error (it guards the third-party
/// decoders that way). What must never happen is a panic escaping the entry point, and
/// `libfuzzer-sys` still aborts on that; so the hook is put back to one that only prints,
/// unless `IBL_FUZZ_STRICT=1` asks to stop at panics inside the decoders too (to find bugs to
/// report upstream).
pub fn init() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        if std::env::var_os("IBL_FUZZ_STRICT").is_none_or(|v| v != "1") {
            std::panic::set_hook(Box::new(|info| {
                eprintln!("panic (a panic escaping the target still aborts): {info}")
            }));
        }
    });
}
