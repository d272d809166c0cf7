//! The memory budget of a run: every reader computes from a file's header what decoding it
//! will allocate and reserves that here before inflating or decoding anything, so a small file
//! declaring a huge image (a decompression bomb) is refused in microseconds instead of taking
//! gigabytes and minutes, and the big buffers are allocated fallibly so that an allocation
//! the system refuses anyway is a one-line error, never an abort.
//!
//! One budget per process: `--max-memory` (every tool, `ibl-cli`'s common flags) or the
//! `IBL_MAX_MEMORY` environment variable (read by every process, the `bake` runner and the
//! tools a ninja file starts included) set it; the default is min(4 GiB, half of the machine's memory). Reservations of readers
//! running at once (the six faces of a folder decode in parallel) add up.

use crate::error::{Error, Result};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

/// The environment variable that sets the budget where no `--max-memory` is given, in the
/// syntax of [`parse_size`].
pub const ENV_VAR: &str = "IBL_MAX_MEMORY";

/// The budget in bytes; 0 until set (then [`default_max_memory`] or [`ENV_VAR`] applies).
static LIMIT: AtomicU64 = AtomicU64::new(0);
/// Bytes reserved by readers running now.
static IN_USE: AtomicU64 = AtomicU64::new(0);

const MIB: u64 = 1 << 20;
const GIB: u64 = 1 << 30;

/// min(4 GiB, half of `MemTotal` in /proc/meminfo); 4 GiB where that cannot be read.
pub fn default_max_memory() -> u64 {
    let total = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|s| mem_total(&s));
    match total {
        Some(t) => (t / 2).clamp(256 * MIB, 4 * GIB),
        None => 4 * GIB,
    }
}

/// `MemTotal` of /proc/meminfo text, in bytes.
fn mem_total(meminfo: &str) -> Option<u64> {
    let line = meminfo.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kb.checked_mul(1024)
}

/// Parses a size: bytes, or a number with K, M, G or T (powers of 1024, an optional `B` or
/// `iB` after it): `512M`, `8G`, `1.5GiB`, `100000000`.
pub fn parse_size(text: &str) -> std::result::Result<u64, String> {
    let t = text.trim();
    let upper = t.to_ascii_uppercase();
    let body = upper
        .strip_suffix("IB")
        .or_else(|| upper.strip_suffix('B'))
        .unwrap_or(&upper);
    let (num, unit) = match body.chars().last() {
        Some('K') => (&body[..body.len() - 1], 1u64 << 10),
        Some('M') => (&body[..body.len() - 1], MIB),
        Some('G') => (&body[..body.len() - 1], GIB),
        Some('T') => (&body[..body.len() - 1], 1u64 << 40),
        _ => (body, 1),
    };
    let bad = || format!("'{text}' is not a size (examples: 512M, 8G, 1.5GiB, 100000000)");
    let v: f64 = num.trim().parse().map_err(|_| bad())?;
    if !v.is_finite() || v <= 0.0 || v * unit as f64 >= u64::MAX as f64 {
        return Err(bad());
    }
    Ok((v * unit as f64) as u64)
}

/// Sets the budget of this process.
pub fn set_max_memory(bytes: u64) {
    LIMIT.store(bytes.max(1), Ordering::Relaxed);
}

/// The budget in bytes: as set, else [`ENV_VAR`], else [`default_max_memory`].
pub fn max_memory() -> u64 {
    let v = LIMIT.load(Ordering::Relaxed);
    if v != 0 {
        return v;
    }
    let v = std::env::var(ENV_VAR)
        .ok()
        .and_then(|s| parse_size(&s).ok())
        .unwrap_or_else(default_max_memory);
    LIMIT.store(v, Ordering::Relaxed);
    v
}

/// A size for messages: "8194 MB" (10^6 bytes, as `ls -h` and most users count).
pub fn human(bytes: u64) -> String {
    if bytes >= 10_000_000 {
        format!("{} MB", bytes / 1_000_000)
    } else if bytes >= 10_000 {
        format!("{} kB", bytes / 1000)
    } else {
        format!("{bytes} bytes")
    }
}

/// Bytes held against the budget until dropped.
#[derive(Debug)]
#[must_use = "the reservation ends when dropped"]
pub struct Reservation(u64);

impl Drop for Reservation {
    fn drop(&mut self) {
        IN_USE.fetch_sub(self.0, Ordering::Relaxed);
    }
}

/// Reserves `bytes` for reading `path` (`what` says for what: "decoding a 16384x8192 JPEG
/// image"), or refuses naming the need, the budget and how to raise it.
pub fn reserve(path: &Path, what: &str, bytes: u64) -> Result<Reservation> {
    let limit = max_memory();
    let mut cur = IN_USE.load(Ordering::Relaxed);
    loop {
        let total = cur.saturating_add(bytes);
        if total > limit {
            let others = if cur > 0 {
                format!(" (with {} held by other inputs)", human(cur))
            } else {
                String::new()
            };
            return Err(Error::Memory {
                path: Some(path.to_path_buf()),
                reason: format!(
                    "{what} needs {}{others}, over the memory budget of {} \
                     (raise it with --max-memory, e.g. --max-memory {}G)",
                    human(bytes),
                    human(limit),
                    total.div_ceil(GIB).max(1)
                ),
            });
        }
        match IN_USE.compare_exchange_weak(cur, total, Ordering::Relaxed, Ordering::Relaxed) {
            Ok(_) => return Ok(Reservation(bytes)),
            Err(now) => cur = now,
        }
    }
}

/// A zero-filled `Vec` of `n` values allocated fallibly: the system refusing the memory is
/// an [`Error::Memory`] naming `path`, not an abort. Zeroed by the allocator (`calloc`: a
/// large one is fresh pages, which the caller's parallel fill is the first to touch; writing
/// the zeros was a serial pass over a decoded image before it).
pub fn try_zeroed<T: bytemuck::Zeroable>(path: &Path, n: usize) -> Result<Vec<T>> {
    bytemuck::allocation::try_zeroed_vec(n)
        .map_err(|_| out_of_memory(path, n.saturating_mul(std::mem::size_of::<T>()) as u64))
}

/// The error of an allocation the system refused.
pub fn out_of_memory(path: &Path, bytes: u64) -> Error {
    Error::Memory {
        path: Some(path.to_path_buf()),
        reason: format!(
            "could not allocate {} (the system is out of memory; the budget is {})",
            human(bytes),
            human(max_memory())
        ),
    }
}

/// Reads a whole file after checking its size against the budget, into a buffer allocated
/// fallibly: a 50 GB file named as an input is refused, not read.
pub fn read_file(path: &Path) -> Result<Vec<u8>> {
    use std::io::Read;
    let mut f = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let len = f.metadata().map_err(|e| Error::io(path, e))?.len();
    let _r = reserve(path, "reading the file", len)?;
    let mut v = Vec::new();
    v.try_reserve_exact(len as usize)
        .map_err(|_| out_of_memory(path, len))?;
    f.read_to_end(&mut v).map_err(|e| Error::io(path, e))?;
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_in_binary_units() {
        assert_eq!(parse_size("512M"), Ok(512 * MIB));
        assert_eq!(parse_size("8g"), Ok(8 * GIB));
        assert_eq!(parse_size("1.5GiB"), Ok(3 * GIB / 2));
        assert_eq!(parse_size("100000"), Ok(100_000));
        assert_eq!(parse_size("2kb"), Ok(2048));
        for bad in ["", "-1G", "0", "lots", "NaNG", "1e30T"] {
            assert!(parse_size(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn meminfo_is_read_in_kilobytes() {
        let m = "MemTotal:       16318412 kB\nMemFree:  1 kB\n";
        assert_eq!(mem_total(m), Some(16318412 * 1024));
        assert_eq!(mem_total("nothing"), None);
        let d = default_max_memory();
        assert!((256 * MIB..=4 * GIB).contains(&d), "{d}");
    }

    #[test]
    fn reservations_add_up_and_are_released() {
        // The budget is process-wide: measure against whatever it is, with room to spare.
        let limit = max_memory();
        let p = Path::new("x.exr");
        let a = reserve(p, "a", limit / 2).unwrap();
        let e = reserve(p, "decoding a 2:1 image", limit / 2 + limit / 4)
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("x.exr: decoding a 2:1 image needs")
                && e.contains("over the memory budget of")
                && e.contains("--max-memory")
                && e.contains("held by other inputs"),
            "{e}"
        );
        drop(a);
        drop(reserve(p, "b", limit / 2 + limit / 4).unwrap());
        assert!(reserve(p, "c", u64::MAX).is_err());
    }

    #[test]
    fn failed_allocations_are_errors() {
        let e = try_zeroed::<f32>(Path::new("big.exr"), usize::MAX / 8).unwrap_err();
        assert!(matches!(e, Error::Memory { .. }), "{e}");
        assert_eq!(try_zeroed::<f32>(Path::new("s"), 3).unwrap(), vec![0.0; 3]);
    }
}
