//! The hostile-input suite, run on the real `irradiance` binary (`--size 8`: a caller that
//! needs a tiny output, which must still refuse to decode a huge input): decompression bombs
//! in every format, lying headers, truncated scans, numbers at the f32 limit and negative
//! texels. Each case asserts the exit code, the one-line message, the child's peak memory
//! (its own `ru_maxrss` from `wait4`) under its bound, and a time bound that only guards
//! against the 50-second decodes of issue 24 (no speed is asserted).

use ibl_core::io::{self, WriteOptions};
use ibl_core::Image;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

const BIN: &str = env!("CARGO_BIN_EXE_irradiance");

/// What one run of the binary did.
struct Run {
    code: i32,
    stderr: String,
    peak_mb: f64,
    seconds: f64,
}

/// Set in the environment of the launcher (this test binary run again, see
/// [`launch_and_measure`]): the binary's arguments, one per line.
const LAUNCH: &str = "IBL_HOSTILE_LAUNCH";

/// Runs `irradiance input -o out --size 8 flags…` and measures the child's own peak
/// resident memory. Linux carries a process's peak RSS across `exec`, and a child spawned
/// from this test process starts with this process's peak (tens of MB of test images), so
/// the binary is started by a fresh, small launcher, this test binary running only
/// [`launch_and_measure`], which reports its child's `ru_maxrss` from `wait4`.
fn run(input: &Path, out: &Path, flags: &[&str]) -> Run {
    let err_path = out.with_extension("stderr");
    let mut args: Vec<String> = vec![
        input.display().to_string(),
        "-o".into(),
        out.display().to_string(),
    ];
    args.extend(["--size", "8", "--threads", "2"].map(String::from));
    args.extend(flags.iter().map(|f| f.to_string()));
    let start = Instant::now();
    let o = Command::new(std::env::current_exe().unwrap())
        .args([
            "--exact",
            "launch_and_measure",
            "--nocapture",
            "--test-threads",
            "1",
        ])
        .env(LAUNCH, args.join("\n"))
        .env("IBL_HOSTILE_STDERR", &err_path)
        .stderr(Stdio::null())
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    let field = |k: &str| -> i64 {
        let at = text.find(k).unwrap_or_else(|| panic!("no {k} in {text}")) + k.len();
        text[at..]
            .split_whitespace()
            .next()
            .unwrap()
            .parse()
            .unwrap()
    };
    Run {
        code: field("CODE=") as i32,
        stderr: std::fs::read_to_string(&err_path).unwrap(),
        peak_mb: field("MAXRSS_KB=") as f64 / 1024.0,
        seconds: start.elapsed().as_secs_f64(),
    }
}

/// The launcher: does nothing unless [`LAUNCH`] is set; then runs the binary with those
/// arguments and prints its exit code and peak RSS (kilobytes) from `wait4`.
#[test]
fn launch_and_measure() {
    let Ok(args) = std::env::var(LAUNCH) else {
        return;
    };
    let err = std::fs::File::create(std::env::var("IBL_HOSTILE_STDERR").unwrap()).unwrap();
    let child = Command::new(BIN)
        .args(args.lines())
        .stdout(Stdio::null())
        .stderr(err)
        .spawn()
        .unwrap();
    let pid = child.id() as libc::pid_t;
    let mut status = 0;
    // SAFETY: an all-zero rusage is valid; wait4 on our own child with valid pointers.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    let r = unsafe { libc::wait4(pid, &mut status, 0, &mut usage) };
    assert_eq!(r, pid, "wait4 failed");
    std::mem::forget(child); // reaped by wait4
    let code = if libc::WIFEXITED(status) {
        libc::WEXITSTATUS(status)
    } else {
        -libc::WTERMSIG(status)
    };
    println!("CODE={code} MAXRSS_KB={}", usage.ru_maxrss);
}

/// Asserts a refusal: exit `code`, one stderr line naming `input` and holding `needle`,
/// peak memory under `mb`, and under 20 s (a bomb decoded took 29-50 s).
fn refused(input: &Path, flags: &[&str], code: i32, needle: &str, mb: f64) -> String {
    let d = tempfile::tempdir().unwrap();
    let r = run(input, &d.path().join("out"), flags);
    let line = r.stderr.trim();
    eprintln!(
        "{}: exit {}, {:.1} MB peak, {:.3} s: {line}",
        input.display(),
        r.code,
        r.peak_mb,
        r.seconds
    );
    assert_eq!(r.code, code, "{line}");
    assert_eq!(line.lines().count(), 1, "not one line: {line}");
    assert!(line.starts_with("irradiance: error: "), "{line}");
    assert!(line.contains(&input.display().to_string()), "{line}");
    assert!(line.contains(needle), "{needle:?} not in: {line}");
    assert!(
        r.peak_mb < mb,
        "peak {:.1} MB over {mb} MB: {line}",
        r.peak_mb
    );
    assert!(r.seconds < 20.0, "{:.1} s: {line}", r.seconds);
    assert!(
        !d.path().join("out").exists()
            || std::fs::read_dir(d.path().join("out"))
                .unwrap()
                .next()
                .is_none(),
        "a refused run wrote outputs"
    );
    line.to_string()
}

fn noise(w: usize, h: usize) -> Image {
    let mut img = Image::new(w, h, 3);
    let mut s = 12345u32;
    for v in img.data.iter_mut() {
        s = s.wrapping_mul(1_103_515_245).wrapping_add(12345);
        *v = ((s >> 16) & 0xff) as f32 / 255.0;
    }
    img
}

fn encoded(name: &str, img: &Image, opts: &WriteOptions) -> Vec<u8> {
    io::encode_image(Path::new(name), img, opts).unwrap()
}

fn jpeg(img: &Image) -> Vec<u8> {
    let rgb: Vec<u8> = img.data.iter().map(|v| (v * 255.0) as u8).collect();
    let mut out = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 90)
        .encode(
            &rgb,
            img.width as u32,
            img.height as u32,
            image::ExtendedColorType::Rgb8,
        )
        .unwrap();
    out
}

fn find(hay: &[u8], needle: &[u8]) -> usize {
    hay.windows(needle.len()).position(|w| w == needle).unwrap()
}

/// A JPEG's SOF0 height and width set to (w, h), its data unchanged.
fn patch_jpeg_size(b: &mut [u8], w: u16, h: u16) {
    let sof = find(b, &[0xFF, 0xC0]);
    b[sof + 5..sof + 7].copy_from_slice(&h.to_be_bytes());
    b[sof + 7..sof + 9].copy_from_slice(&w.to_be_bytes());
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

/// A zstd frame of `n` zero bytes made of RLE blocks (RFC 8878 §3.1.1: a single-segment
/// frame with an 8-byte content size; blocks of type 1 repeat one byte up to 128 KiB): 4
/// bytes per 128 KiB, the cheapest bomb zstd allows.
fn zstd_zeros(n: u64) -> Vec<u8> {
    let mut f = vec![0x28, 0xB5, 0x2F, 0xFD, 0xE0];
    f.extend(n.to_le_bytes());
    let mut left = n;
    while left > 0 {
        let k = left.min(128 * 1024);
        left -= k;
        let last = (left == 0) as u32;
        let header = last | (1 << 1) | ((k as u32) << 3);
        f.extend(&header.to_le_bytes()[..3]);
        f.push(0);
    }
    f
}

/// A KTX2 cube of one RGBA32F level of `size`² faces whose only level is `level`, stored
/// zstd-supercompressed (scheme 2) when `zstd`.
fn ktx2_cube(size: u32, level: &[u8], zstd: bool) -> Vec<u8> {
    let mut b = vec![
        0xAB, 0x4B, 0x54, 0x58, 0x20, 0x32, 0x30, 0xBB, 0x0D, 0x0A, 0x1A, 0x0A,
    ];
    let raw = size as u64 * size as u64 * 16 * 6;
    for v in [109u32, 4, size, size, 0, 0, 6, 1, if zstd { 2 } else { 0 }] {
        b.extend(v.to_le_bytes());
    }
    b.extend([0u8; 16]); // dfd and kvd offsets and lengths
    b.extend([0u8; 16]); // sgd
    b.extend(104u64.to_le_bytes());
    b.extend((level.len() as u64).to_le_bytes());
    b.extend(raw.to_le_bytes());
    b.extend(level);
    b
}

#[test]
fn bombs_in_every_format_are_refused_fast_and_small() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    // zstd KTX2 of zeros declaring 6688² RGBA32F faces: a ~130 KB file inflating to 4.3 GB
    // (issue 24: 8,194 MB and 50 s). Within zstd's ratio, so the budget refuses it.
    let n = 6688u32;
    let bomb = ktx2_cube(n, &zstd_zeros(n as u64 * n as u64 * 16 * 6), true);
    assert!(bomb.len() < 140_000, "{}", bomb.len());
    let p = write(dir, "zeros.ktx2", &bomb);
    let line = refused(&p, &[], 3, "over the memory budget", 100.0);
    assert!(line.contains("--max-memory"), "{line}");
    // The same under a budget the user set: named in the message.
    let line = refused(&p, &["--max-memory", "1G"], 3, "budget of 1073 MB", 100.0);
    assert!(line.contains("6688x6688"), "{line}");

    // 16384² declared by files of a few hundred bytes: the data cannot hold what the header
    // says, refused as invalid before any decoding.
    let small = noise(32, 16);
    let mut jpg = jpeg(&small);
    patch_jpeg_size(&mut jpg, 16384, 8192);
    let p = write(dir, "bomb.jpg", &jpg);
    refused(&p, &[], 2, "cannot hold", 100.0);
    // Square, it is not a shape an environment can have: refused on the header alone.
    patch_jpeg_size(&mut jpg, 16384, 16384);
    let p = write(dir, "square.jpg", &jpg);
    refused(&p, &[], 3, "layout of a 16384x16384 image", 100.0);

    let mut png = encoded(
        "a.png",
        &small,
        &WriteOptions {
            png_bits: 8,
            ..Default::default()
        },
    );
    png[16..20].copy_from_slice(&16384u32.to_be_bytes());
    png[20..24].copy_from_slice(&8192u32.to_be_bytes());
    let p = write(dir, "bomb.png", &png);
    refused(&p, &[], 2, "cannot inflate", 100.0);

    let mut exr = encoded("a.exr", &small, &WriteOptions::default());
    let at = find(&exr, b"dataWindow\0box2i\0") + "dataWindow\0box2i\0".len() + 4;
    exr[at + 8..at + 12].copy_from_slice(&16383i32.to_le_bytes());
    exr[at + 12..at + 16].copy_from_slice(&8191i32.to_le_bytes());
    let p = write(dir, "bomb.exr", &exr);
    refused(&p, &[], 2, "truncated or damaged EXR", 100.0);

    let mut hdr = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 8192 +X 16384\n".to_vec();
    hdr.extend([2, 2, 0x40, 0x00, 0x80, 0, 0x80, 0, 0x80, 0, 0x80, 0]);
    let p = write(dir, "bomb.hdr", &hdr);
    refused(&p, &[], 2, "cannot hold the 8192 scan lines", 100.0);
}

#[test]
fn valid_but_large_inputs_are_refused_by_the_budget_not_decoded() {
    // A real 2048x1024 EXR (about 25 MB decoded) is read as a stream: a budget below its
    // window of rows refuses it, naming the size, the budget and the flag, before a row is
    // decoded; one of 4 MB, a sixth of the image, bakes (the image is never held whole).
    let d = tempfile::tempdir().unwrap();
    let p = write(
        d.path(),
        "big.exr",
        &encoded("a.exr", &noise(2048, 1024), &WriteOptions::default()),
    );
    let line = refused(&p, &["--max-memory", "500K"], 3, "2048x1024", 100.0);
    assert!(line.contains("budget of 512 kB"), "{line}");
    let r = run(&p, &d.path().join("ok"), &["--max-memory", "4M"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    // Its exact cube from the source's own texels needs the whole image after all (25 MB):
    // refused before a row is read.
    let exact = ["--max-memory", "8M", "--exact", "--exact-source-width", "0"];
    let line = refused(
        &p,
        &exact,
        3,
        "2048x1024 equirect the exact cube convolves",
        100.0,
    );
    assert!(line.contains("budget of 8388 kB"), "{line}");
    // Below the streaming threshold the image is decoded whole: 1024x512 (a 5 MB file, 6 MB
    // decoded) is refused under 8 MB.
    let small = write(
        d.path(),
        "small.exr",
        &encoded("a.exr", &noise(1024, 512), &WriteOptions::default()),
    );
    refused(&small, &["--max-memory", "8M"], 3, "1024x512", 100.0);
}

#[test]
fn short_scans_and_lying_headers_are_refused() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    // Issue 24 item 3: a 64x32 noise JPEG whose SOF says 128x64 (exit 0 before, the missing
    // three quarters made up by the decoder).
    let mut b = jpeg(&noise(64, 32));
    patch_jpeg_size(&mut b, 128, 64);
    let p = write(dir, "short.jpg", &b);
    let line = refused(&p, &[], 2, "scan data ends after", 100.0);
    assert!(line.contains("128x64"), "{line}");

    // An EXR whose last chunk offset points outside the file.
    let good = encoded("a.exr", &noise(64, 32), &WriteOptions::default());
    let mut b = good.clone();
    // The offset table follows the header's terminating null: find the first chunk offset by
    // value (the smallest offset), and point the last entry past the end.
    let meta_end = {
        let mut at = 8; // magic and version
        while b[at] != 0 {
            // name\0type\0size value
            let name_end = at + b[at..].iter().position(|&c| c == 0).unwrap();
            let type_end = name_end + 1 + b[name_end + 1..].iter().position(|&c| c == 0).unwrap();
            let size = i32::from_le_bytes(b[type_end + 1..type_end + 5].try_into().unwrap());
            at = type_end + 5 + size as usize;
        }
        at + 1
    };
    let first = u64::from_le_bytes(b[meta_end..meta_end + 8].try_into().unwrap()) as usize;
    let chunks = (first - meta_end) / 8;
    let last = meta_end + 8 * (chunks - 1);
    b[last..last + 8].copy_from_slice(&(good.len() as u64 + 100).to_le_bytes());
    let p = write(dir, "missing.exr", &b);
    refused(&p, &[], 2, "is missing", 100.0);
    // Two entries naming one chunk: the other chunk's lines would stay black.
    let mut b = good.clone();
    let second = u64::from_le_bytes(b[meta_end + 8..meta_end + 16].try_into().unwrap());
    b[meta_end..meta_end + 8].copy_from_slice(&second.to_le_bytes());
    let p = write(dir, "twice.exr", &b);
    refused(&p, &[], 2, "damaged EXR", 100.0);

    // A KTX2 level whose uncompressedByteLength lies: the message says which field.
    let level = vec![0u8; 4 * 4 * 16 * 6];
    let mut b = ktx2_cube(4, &level, false);
    b[80 + 16..80 + 24].copy_from_slice(&7u64.to_le_bytes());
    let p = write(dir, "lying.ktx2", &b);
    let line = refused(&p, &[], 2, "uncompressedByteLength says 7 bytes", 100.0);
    assert!(!line.contains("holds 1536 bytes, expected 1536"), "{line}");
}

#[test]
fn damaged_zstd_levels_fail_their_checksum() {
    let d = tempfile::tempdir().unwrap();
    let src = write(
        d.path(),
        "env.exr",
        &encoded("a.exr", &noise(64, 32), &WriteOptions::default()),
    );
    let out = d.path().join("baked");
    let r = run(&src, &out, &["--layout", "ktx2", "--zstd", "3"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let cube = out.join("irradiance.ktx2");
    let mut b = std::fs::read(&cube).unwrap();
    // The frame's last 4 bytes are its content checksum (the writer sets the flag).
    let off = u64::from_le_bytes(b[80..88].try_into().unwrap()) as usize;
    let len = u64::from_le_bytes(b[88..96].try_into().unwrap()) as usize;
    assert_eq!(b[off + 4] & 0x04, 0x04, "Content_Checksum_Flag not set");
    b[off + len - 1] ^= 0x55;
    let p = write(d.path(), "rot.ktx2", &b);
    refused(&p, &[], 2, "checksum mismatch", 100.0);
}

#[test]
fn finite_input_gives_finite_output_or_a_clear_error() {
    let d = tempfile::tempdir().unwrap();
    let mut img = Image::new(64, 32, 3);
    img.data.fill(1e38);
    let p = write(
        d.path(),
        "bright.exr",
        &encoded("a.exr", &img, &WriteOptions::default()),
    );
    let line = refused(&p, &[], 2, "beyond the largest 32-bit float", 200.0);
    assert!(!line.contains("--format rgba32f"), "{line}");
    // 1e37: E/π = 1e37 and L00 = 3.5e37 fit; every output value is finite.
    img.data.fill(1e37);
    let p = write(
        d.path(),
        "bright37.exr",
        &encoded("a.exr", &img, &WriteOptions::default()),
    );
    for exact in [false, true] {
        let out = d.path().join(format!("o{exact}"));
        let flags: &[&str] = if exact { &["--exact"] } else { &["--from-sh"] };
        let r = run(&p, &out, flags);
        assert_eq!(r.code, 0, "{}", r.stderr);
        let sh: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.join("sh.json")).unwrap()).unwrap();
        let l00 = sh["radiance"][0][0].as_f64().unwrap();
        let want = 1e37 * (4.0 * std::f64::consts::PI).sqrt();
        assert!((l00 / want - 1.0).abs() < 1e-4, "{l00}");
        for f in ["px", "nx", "py", "ny", "pz", "nz"] {
            let face =
                io::read_image(&out.join(format!("{f}.exr")), io::ColorSpace::Linear).unwrap();
            for v in &face.data {
                assert!(
                    v.is_finite() && (v / 1e37 - 1.0).abs() < 2e-3,
                    "{f} {v} exact {exact}"
                );
            }
        }
    }
}

#[test]
fn negative_texels_are_clamped_with_their_power_kept_or_refused() {
    // Radiance 1 everywhere except a band of rows at -0.5: the clamp adds exactly the
    // band's solid angle × 0.5 (× 3 channels) to 4π × 3 minus that.
    let (w, h) = (64, 32);
    let mut img = Image::new(w, h, 3);
    img.data.fill(1.0);
    let rows = 4..8;
    for j in rows.clone() {
        for v in &mut img.data[j * w * 3..(j + 1) * w * 3] {
            *v = -0.5;
        }
    }
    let omega: f64 = rows
        .clone()
        .map(|j| ibl_core::equirect::row_solid_angle(j, w, h) * w as f64)
        .sum();
    let power = 4.0 * std::f64::consts::PI - 1.5 * omega; // per channel, as read
    let share = 100.0 * 0.5 * omega / power;
    let d = tempfile::tempdir().unwrap();
    let p = write(
        d.path(),
        "neg.exr",
        &encoded("a.exr", &img, &WriteOptions::default()),
    );
    let r = run(&p, &d.path().join("clamp"), &[]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let want = format!("adding +{share:.3}% of the environment's power");
    assert!(r.stderr.contains(&want), "{want:?} not in {}", r.stderr);
    assert!(
        r.stderr
            .contains(&format!("clamped {} negative", 4 * w * 3)),
        "{}",
        r.stderr
    );
    let l00 = |dir: &str| -> f64 {
        let v: serde_json::Value =
            serde_json::from_slice(&std::fs::read(d.path().join(dir).join("sh.json")).unwrap())
                .unwrap();
        v["radiance"][0][0].as_f64().unwrap()
    };
    let r = run(&p, &d.path().join("keep"), &["--negative", "keep"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stderr.contains("kept 768 negative texel values"),
        "{}",
        r.stderr
    );
    // L00 = ∫ L Y00 dω: the clamp's L00 over the kept one is the power ratio.
    let y00 = 0.5 / std::f64::consts::PI.sqrt();
    let (c, k) = (l00("clamp"), l00("keep"));
    assert!((k / (power * y00) - 1.0).abs() < 1e-3, "{k}");
    assert!(
        (c / ((power + 0.5 * omega) * y00) - 1.0).abs() < 1e-3,
        "{c}"
    );
    refused(
        &p,
        &["--negative", "refuse"],
        2,
        "refused by --negative refuse",
        200.0,
    );
}
