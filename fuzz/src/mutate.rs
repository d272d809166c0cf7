//! A small deterministic mutation fuzzer (no coverage feedback): seeded `Pcg32` edits of a seed
//! corpus, every input run under `catch_unwind`. It is what `cargo test` runs on the image
//! readers (`crates/ibl-core/tests/fuzz_regressions.rs` includes this file by path) and what
//! `scripts/fuzz.sh` falls back to when cargo-fuzz cannot build. Only `ibl_core` and `std`.

use ibl_core::sampling::Pcg32;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Regular files of `dir` (not hidden), sorted; none when it does not exist.
pub fn files_in(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok())
                .map(|e| e.path())
                .filter(|p| p.is_file())
                .filter(|p| !p.file_name().unwrap().to_string_lossy().starts_with('.'))
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

/// The seeds of `target`: `fuzz/corpus/<target>/*` and `fuzz/regressions/<target>/*`.
pub fn seeds(fuzz_dir: &Path, target: &str) -> Vec<Vec<u8>> {
    let mut v: Vec<Vec<u8>> = files_in(&fuzz_dir.join("corpus").join(target))
        .into_iter()
        .chain(files_in(&fuzz_dir.join("regressions").join(target)))
        .filter_map(|p| std::fs::read(p).ok())
        .collect();
    if v.is_empty() {
        v.push(Vec::new());
    }
    v
}

/// FNV-1a, to name crash files by content and derive streams from target names.
pub fn fnv1a(b: &[u8]) -> u64 {
    b.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &x| {
        (h ^ x as u64).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// CRC-32 (ISO 3309, as PNG uses).
pub fn crc32(b: &[u8]) -> u32 {
    let mut c = 0xffff_ffffu32;
    for &x in b {
        c ^= x as u32;
        for _ in 0..8 {
            c = if c & 1 != 0 {
                0xedb8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
    }
    !c
}

/// Recomputes the CRC of every whole chunk of a PNG, so mutations reach past the CRC check
/// (cargo-fuzz builds the `png` crate with `--cfg fuzzing`, which skips it; a test cannot).
pub fn fix_png_crcs(b: &mut [u8]) {
    let mut at = 8;
    while at + 12 <= b.len() {
        let len = u32::from_be_bytes(b[at..at + 4].try_into().unwrap()) as usize;
        let Some(end) = (at + 8).checked_add(len).filter(|&e| e + 4 <= b.len()) else {
            break;
        };
        let crc = crc32(&b[at + 4..end]);
        b[end..end + 4].copy_from_slice(&crc.to_be_bytes());
        at = end + 4;
    }
}

/// Tokens worth inserting, per target (the text formats mostly).
pub fn dictionary(target: &str) -> &'static [&'static str] {
    match target {
        "hdr" => &[
            "#?RADIANCE\n",
            "FORMAT=32-bit_rle_rgbe\n",
            "FORMAT=32-bit_rle_xyze\n",
            "EXPOSURE=",
            "\n\n",
            "-Y ",
            "+Y ",
            "-X ",
            "+X ",
            "\x02\x02",
        ],
        "pipeline" => &[
            "Pipeline(",
            "(",
            ")",
            "[",
            "]",
            "{",
            "}",
            ":",
            ",",
            "\"",
            "r#\"",
            "\"#",
            "/*",
            "*/",
            "//",
            "\n",
            "Some(",
            "None",
            "true",
            "false",
            "1e309",
            "-1e309",
            "NaN",
            "inf",
            "-0.0",
            "0x",
            "output:",
            "inputs:",
            "stages:",
            "outputs:",
            "scene:",
            "id:",
            "kind:",
            "reads:",
            "params:",
            "out:",
            "File(",
            "Folder(",
            "Glob(",
            "\"**/*\"",
            "\"../\"",
            "probes:",
            "materials:",
            "env:",
            "max_roughness:",
            "served_by:",
            "ShExp",
            "SplitSum",
            "folder:",
            "model:",
            "Ggx",
            "AshikhminShirley(n_u: 1e6, n_v: 0)",
            "bump_mapped:",
            "tpr_map:",
            "tpr_params:",
            "\"equirect-to-cube\"",
            "\"prefilter\"",
            "\"irradiance\"",
            "\"dfg\"",
            "\"shexp-fit\"",
            "\"tpr-map\"",
            "size:",
            "samples:",
            "quality:",
            "roughness:",
        ],
        "ownership" => &[
            "\0",
            "\n",
            "..",
            "../",
            "./",
            "/",
            "in/",
            "out/",
            "up/",
            "sub/",
            "link.exr",
            "px.exr",
            "root/",
            "{\"files\":{",
            "\"tools\":[",
            "\":\"",
        ],
        _ => &[],
    }
}

fn below(rng: &mut Pcg32, n: usize) -> usize {
    ((rng.next_u32() as u64 * n as u64) >> 32) as usize
}

const INTERESTING_U8: [u8; 8] = [0, 1, 0x7f, 0x80, 0xfe, 0xff, b'0', b'\n'];
const INTERESTING_U32: [u32; 24] = [
    0,
    1,
    2,
    3,
    4,
    6,
    7,
    8,
    15,
    16,
    31,
    32,
    64,
    255,
    256,
    0x7fff,
    0x8000,
    0xffff,
    0x1_0000,
    0x0fff_ffff,
    0x7fff_ffff,
    0x8000_0000,
    0xffff_fffe,
    0xffff_ffff,
];
const INTERESTING_NUMBERS: [&str; 14] = [
    "0",
    "1",
    "-1",
    "2",
    "7",
    "255",
    "65535",
    "65536",
    "16384",
    "2147483648",
    "4294967296",
    "99999999999999999999999",
    "1e38",
    "0.5",
];

/// One to four random edits of a random seed.
pub fn mutate(rng: &mut Pcg32, seeds: &[Vec<u8>], dict: &[&str]) -> Vec<u8> {
    let mut b = seeds[below(rng, seeds.len())].clone();
    for _ in 0..1 + below(rng, 4) {
        let n = b.len();
        match below(rng, 11) {
            0 if n > 0 => {
                let i = below(rng, n);
                b[i] ^= 1 << below(rng, 8);
            }
            1 if n > 0 => {
                let i = below(rng, n);
                b[i] = INTERESTING_U8[below(rng, INTERESTING_U8.len())];
            }
            2 => b.truncate(below(rng, n + 1)),
            3 => {
                let at = below(rng, n + 1);
                let k = 1 + below(rng, 16);
                let ins: Vec<u8> = (0..k).map(|_| rng.next_u32() as u8).collect();
                b.splice(at..at, ins);
            }
            4 if n > 0 => {
                let at = below(rng, n);
                let k = 1 + below(rng, (n - at).min(64));
                b.drain(at..at + k);
            }
            // A length, size, offset or count field: header fields of EXR and KTX2 are
            // little-endian u32/u64, mostly at 4-byte-aligned offsets.
            5 if n >= 4 => {
                let at = if below(rng, 2) == 0 {
                    below(rng, n / 4) * 4
                } else {
                    below(rng, n - 3)
                };
                let v = if below(rng, 4) == 0 {
                    (n as u32)
                        .wrapping_add(below(rng, 3) as u32)
                        .wrapping_sub(1)
                } else {
                    INTERESTING_U32[below(rng, INTERESTING_U32.len())]
                };
                b[at..at + 4].copy_from_slice(&v.to_le_bytes());
            }
            6 if n >= 8 => {
                let at = below(rng, n / 8) * 8;
                let v = INTERESTING_U32[below(rng, INTERESTING_U32.len())] as u64
                    | if below(rng, 2) == 0 {
                        0
                    } else {
                        0xffff_ffff << 32
                    };
                b[at..at + 8].copy_from_slice(&v.to_le_bytes());
            }
            // A decimal number of a text header (HDR's "-Y 8 +X 16", RON values).
            7 => {
                let starts: Vec<usize> = (0..n)
                    .filter(|&i| b[i].is_ascii_digit() && (i == 0 || !b[i - 1].is_ascii_digit()))
                    .take(64)
                    .collect();
                if !starts.is_empty() {
                    let s = starts[below(rng, starts.len())];
                    let e = (s..n).find(|&i| !b[i].is_ascii_digit()).unwrap_or(n);
                    let num = INTERESTING_NUMBERS[below(rng, INTERESTING_NUMBERS.len())];
                    b.splice(s..e, num.bytes());
                }
            }
            // Copies a block of the input elsewhere in it (repeats chunks, table entries).
            8 if n > 0 => {
                let from = below(rng, n);
                let k = 1 + below(rng, (n - from).min(256));
                let piece = b[from..from + k].to_vec();
                let to = below(rng, n);
                let end = (to + k).min(n);
                b[to..end].copy_from_slice(&piece[..end - to]);
            }
            // Splices the tail of another seed.
            9 => {
                let other = &seeds[below(rng, seeds.len())];
                let cut = below(rng, n + 1);
                let from = below(rng, other.len() + 1);
                b.truncate(cut);
                b.extend_from_slice(&other[from..]);
            }
            10 if !dict.is_empty() => {
                let at = below(rng, n + 1);
                let word = dict[below(rng, dict.len())];
                b.splice(at..at, word.bytes());
            }
            _ => {}
        }
    }
    b
}

/// Runs one input; the panic message if it panicked.
pub fn panics(run: &dyn Fn(&[u8]), data: &[u8]) -> Option<String> {
    catch_unwind(AssertUnwindSafe(|| run(data))).err().map(|e| {
        e.downcast_ref::<String>()
            .cloned()
            .or_else(|| e.downcast_ref::<&str>().map(|s| s.to_string()))
            .unwrap_or_else(|| "non-string panic".into())
    })
}

/// What a fuzzing run did.
pub struct FuzzRun {
    pub runs: u64,
    pub elapsed: Duration,
    /// Inputs that panicked, with the message (at most 10: the run stops there).
    pub crashes: Vec<(Vec<u8>, String)>,
}

/// Mutates `seeds` and runs `run` on each input until `iterations` inputs or `budget` time.
pub fn fuzz(
    target: &str,
    seeds: &[Vec<u8>],
    seed: u64,
    iterations: u64,
    budget: Duration,
    run: &dyn Fn(&[u8]),
) -> FuzzRun {
    let dict = dictionary(target);
    let mut rng = Pcg32::new(seed, fnv1a(target.as_bytes()));
    let start = Instant::now();
    let mut out = FuzzRun {
        runs: 0,
        elapsed: Duration::ZERO,
        crashes: Vec::new(),
    };
    while out.runs < iterations && start.elapsed() < budget {
        let mut input = mutate(&mut rng, seeds, dict);
        if target == "png" && below(&mut rng, 8) != 0 {
            fix_png_crcs(&mut input);
        }
        out.runs += 1;
        if let Some(msg) = panics(run, &input) {
            out.crashes.push((input, msg));
            if out.crashes.len() >= 10 {
                break;
            }
        }
    }
    out.elapsed = start.elapsed();
    out
}

/// Writes crash inputs as `crash-<fnv1a>` into `dir`; one line per crash (path: message).
pub fn save_crashes(dir: &Path, crashes: &[(Vec<u8>, String)]) -> Vec<String> {
    std::fs::create_dir_all(dir).unwrap();
    crashes
        .iter()
        .map(|(input, msg)| {
            let p = dir.join(format!("crash-{:016x}", fnv1a(input)));
            std::fs::write(&p, input).unwrap();
            format!("{}: {msg}", p.display())
        })
        .collect()
}

/// The time-budgeted run of `scripts/fuzz.sh`'s fallback: `FUZZ_SECONDS` per target (default
/// 60), `FUZZ_SEED` (default: from the clock), `FUZZ_TARGETS` (comma list, default all of
/// `targets`). Crash inputs go into `fuzz/regressions/<target>/`; the report lines of the
/// crashes (empty when none).
pub fn long_run(fuzz_dir: &Path, targets: &[&str], run: &dyn Fn(&str, &[u8])) -> Vec<String> {
    let secs: u64 = std::env::var("FUZZ_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(60);
    let seed: u64 = std::env::var("FUZZ_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .unwrap()
                .as_nanos() as u64
        });
    let wanted = std::env::var("FUZZ_TARGETS").unwrap_or_default();
    let mut report = Vec::new();
    for &t in targets {
        if !wanted.is_empty() && !wanted.split(',').any(|w| w.trim() == t) {
            continue;
        }
        let corpus = seeds(fuzz_dir, t);
        let r = fuzz(
            t,
            &corpus,
            seed,
            u64::MAX,
            Duration::from_secs(secs),
            &|d| run(t, d),
        );
        let el = r.elapsed.as_secs_f64();
        eprintln!(
            "fuzz {t}: seed {seed}, {} inputs in {el:.1} s ({:.0}/s), {} panics",
            r.runs,
            r.runs as f64 / el.max(1e-9),
            r.crashes.len()
        );
        report.extend(save_crashes(
            &fuzz_dir.join("regressions").join(t),
            &r.crashes,
        ));
    }
    report
}

/// Replays every kept regression input and corpus seed of `targets`; one line per panic.
pub fn replay(fuzz_dir: &Path, targets: &[&str], run: &dyn Fn(&str, &[u8])) -> Vec<String> {
    let mut failures = Vec::new();
    for &t in targets {
        let files: Vec<PathBuf> = ["regressions", "corpus"]
            .iter()
            .flat_map(|d| files_in(&fuzz_dir.join(d).join(t)))
            .collect();
        eprintln!("{t}: replaying {} regression and seed files", files.len());
        for p in files {
            let data = std::fs::read(&p).unwrap();
            if let Some(msg) = panics(&|d| run(t, d), &data) {
                failures.push(format!("{}: {msg}", p.display()));
            }
        }
    }
    failures
}

/// The deterministic quick run the test suites do: `iterations` mutated inputs per target from
/// `seed`, crash inputs saved under `crash_dir/<target>/`; one line per crash.
pub fn quick_run(
    fuzz_dir: &Path,
    targets: &[&str],
    seed: u64,
    iterations: u64,
    crash_dir: &Path,
    run: &dyn Fn(&str, &[u8]),
) -> Vec<String> {
    let mut report = Vec::new();
    for &t in targets {
        let corpus = seeds(fuzz_dir, t);
        let r = fuzz(
            t,
            &corpus,
            seed,
            iterations,
            Duration::from_secs(10),
            &|d| run(t, d),
        );
        eprintln!(
            "{t}: {} mutated inputs in {:.2} s, {} panics",
            r.runs,
            r.elapsed.as_secs_f64(),
            r.crashes.len()
        );
        report.extend(save_crashes(&crash_dir.join(t), &r.crashes));
    }
    report
}
