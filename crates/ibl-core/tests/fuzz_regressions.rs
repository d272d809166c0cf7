//! Fuzz regressions and a built-in mutation fuzzer for every image reader (EXR, HDR, PNG/JPEG,
//! KTX2): no input may make them panic, only return errors.
//!
//! - every file under `fuzz/regressions/<target>/` (crashes the fuzzers found, kept) and
//!   `fuzz/corpus/<target>/` (the seeds) is replayed through the very entry points the cargo-fuzz
//!   targets run (`fuzz/src/images.rs`, included below by path);
//! - a small deterministic mutation fuzzer (seeded `Pcg32`: bit flips, interesting bytes,
//!   truncations, insertions, deletions, corrupted length fields and numbers, splices) runs over
//!   the seed corpus for a few thousand iterations in `cargo test`, and for a time budget in
//!   `mutation_fuzz_long` (ignored; `scripts/fuzz.sh` runs it when cargo-fuzz cannot). The
//!   mutator is `fuzz/src/mutate.rs`, shared with the fuzz crate;
//! - `regenerate_seed_corpus` (ignored) rebuilds `fuzz/corpus/{exr,hdr,png,ktx2}/seed-*` from
//!   the fixtures and generated data.

#[path = "../../../fuzz/src/images.rs"]
#[allow(dead_code)]
mod images;
#[path = "../../../fuzz/src/mutate.rs"]
#[allow(dead_code)]
mod mutate;

use ibl_core::cube::{CubeMips, Cubemap};
use ibl_core::image::Image;
use ibl_core::io::{self, ktx2, ColorSpace, FloatDepth, WriteOptions};
use ibl_testkit::workspace_root as workspace;
use images::{run_image_target, IMAGE_TARGETS};
use mutate::{crc32, files_in};
use std::path::{Path, PathBuf};

fn fuzz_dir() -> PathBuf {
    workspace().join("fuzz")
}

#[test]
fn regressions_and_seeds_do_not_panic() {
    let failures = mutate::replay(&fuzz_dir(), &IMAGE_TARGETS, &run_image_target);
    assert!(failures.is_empty(), "panics:\n{}", failures.join("\n"));
}

#[test]
fn regressions_are_refused_with_an_error() {
    // The crashes kept are malformed files: each must now be an error naming the file, found
    // before any decoder panics. Except `guarded-*`: their panic is in a third-party decoder,
    // which `io::guard` turns into an error; and some of those panics are overflow checks of
    // arithmetic meant to wrap (the `exr` crate's B44, ported from C), so without overflow
    // checks (release) such a file may decode.
    for t in IMAGE_TARGETS {
        for p in files_in(&fuzz_dir().join("regressions").join(t)) {
            let data = std::fs::read(&p).unwrap();
            let err = images::decode_target(t, &data).err();
            let guarded = p
                .file_name()
                .unwrap()
                .to_string_lossy()
                .starts_with("guarded-");
            let Some(err) = err else {
                assert!(
                    guarded && !cfg!(debug_assertions),
                    "{} decodes",
                    p.display()
                );
                continue;
            };
            eprintln!("{}: {err}", p.display());
            assert!(err.to_string().starts_with("f."), "{err}");
            assert!(
                guarded || !err.to_string().contains("the decoder failed"),
                "{}: {err}",
                p.display()
            );
        }
    }
}

#[test]
fn every_seed_is_a_valid_file() {
    // Seeds exist to lead the fuzzers into the decoders' success paths: each must decode.
    for t in IMAGE_TARGETS {
        let files = files_in(&fuzz_dir().join("corpus").join(t));
        assert!(
            !files.is_empty(),
            "no seeds for {t}: run regenerate_seed_corpus"
        );
        for p in files {
            let data = std::fs::read(&p).unwrap();
            let ok = images::decode_target(t, &data);
            assert!(ok.is_ok(), "{}: {}", p.display(), ok.unwrap_err());
        }
    }
}

#[test]
fn mutation_fuzz_quick() {
    // 4000 inputs per reader: deterministic, well under a second.
    let crash_dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("fuzz-crashes");
    let report = mutate::quick_run(
        &fuzz_dir(),
        &IMAGE_TARGETS,
        0x1b1_f022,
        4000,
        &crash_dir,
        &run_image_target,
    );
    assert!(
        report.is_empty(),
        "decoders panicked (copy the inputs into fuzz/regressions/<target>/):\n{}",
        report.join("\n")
    );
}

/// The long run `scripts/fuzz.sh` falls back to when cargo-fuzz cannot run (see
/// `mutate::long_run` for `FUZZ_SECONDS`, `FUZZ_SEED`, `FUZZ_TARGETS`).
#[test]
#[ignore]
fn mutation_fuzz_long() {
    let report = mutate::long_run(&fuzz_dir(), &IMAGE_TARGETS, &run_image_target);
    assert!(report.is_empty(), "panics:\n{}", report.join("\n"));
}

// ---------------------------------------------------------------------------------------------
// The seed corpus.

/// Box-downsizes `img` by an integer factor.
fn downsize(img: &Image, k: usize) -> Image {
    let (w, h) = (img.width / k, img.height / k);
    let mut out = Image::new(w, h, img.channels);
    for y in 0..h {
        for x in 0..w {
            for c in 0..img.channels {
                let mut acc = 0.0f64;
                for b in 0..k {
                    for a in 0..k {
                        acc += img.texel(x * k + a, y * k + b)[c] as f64;
                    }
                }
                out.texel_mut(x, y)[c] = (acc / (k * k) as f64) as f32;
            }
        }
    }
    out
}

fn exr_seed(img: &Image, names: &[&str], half: bool, encoding: exr::prelude::Encoding) -> Vec<u8> {
    use exr::prelude::*;
    let n = img.width * img.height;
    let list: SmallVec<[AnyChannel<FlatSamples>; 4]> = names
        .iter()
        .enumerate()
        .map(|(c, name)| {
            let plane = (0..n).map(|k| img.data[k * img.channels + c.min(img.channels - 1)]);
            let samples = if half {
                FlatSamples::F16(plane.map(f16::from_f32).collect())
            } else {
                FlatSamples::F32(plane.collect())
            };
            AnyChannel::new(*name, samples)
        })
        .collect();
    let layer = Layer::new(
        (img.width, img.height),
        LayerAttributes::default(),
        encoding,
        AnyChannels::sort(list),
    );
    let mut out = std::io::Cursor::new(Vec::new());
    exr::image::Image::from_layer(layer)
        .write()
        .to_buffered(&mut out)
        .unwrap();
    out.into_inner()
}

fn exr_u32_seed() -> Vec<u8> {
    use exr::prelude::*;
    let samples = FlatSamples::U32((0..32u32).map(|k| k * 1000).collect());
    let layer = Layer::new(
        (8, 4),
        LayerAttributes::default(),
        Encoding::UNCOMPRESSED,
        AnyChannels::sort(SmallVec::from_vec(vec![AnyChannel::new("Z", samples)])),
    );
    let mut out = std::io::Cursor::new(Vec::new());
    exr::image::Image::from_layer(layer)
        .write()
        .to_buffered(&mut out)
        .unwrap();
    out.into_inner()
}

/// zlib stream of stored (uncompressed) deflate blocks.
fn zlib_stored(data: &[u8]) -> Vec<u8> {
    let mut z = vec![0x78, 0x01];
    let chunks: Vec<&[u8]> = if data.is_empty() {
        vec![&[]]
    } else {
        data.chunks(65535).collect()
    };
    for (i, c) in chunks.iter().enumerate() {
        z.push((i + 1 == chunks.len()) as u8);
        z.extend((c.len() as u16).to_le_bytes());
        z.extend((!(c.len() as u16)).to_le_bytes());
        z.extend(*c);
    }
    let (mut a, mut b) = (1u32, 0u32);
    for &x in data {
        a = (a + x as u32) % 65521;
        b = (b + a) % 65521;
    }
    z.extend(((b << 16) | a).to_be_bytes());
    z
}

/// A hand-built PNG: IHDR, `extra` chunks, one IDAT holding `raw` (filtered scanlines), IEND.
fn png_seed(
    w: u32,
    h: u32,
    depth: u8,
    color: u8,
    interlace: u8,
    extra: &[(&[u8; 4], Vec<u8>)],
    raw: &[u8],
) -> Vec<u8> {
    let mut out = vec![0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a];
    let mut chunk = |kind: &[u8; 4], body: &[u8]| {
        out.extend((body.len() as u32).to_be_bytes());
        let mut c = kind.to_vec();
        c.extend(body);
        out.extend(&c);
        out.extend(crc32(&c).to_be_bytes());
    };
    let mut ihdr = Vec::new();
    ihdr.extend(w.to_be_bytes());
    ihdr.extend(h.to_be_bytes());
    ihdr.extend([depth, color, 0, 0, interlace]);
    chunk(b"IHDR", &ihdr);
    for (k, body) in extra {
        chunk(k, body);
    }
    chunk(b"IDAT", &zlib_stored(raw));
    chunk(b"IEND", &[]);
    out
}

/// Scanlines (filter byte 0) of a `w`×`h` image of `bits`-per-pixel samples from `px(x, y)`,
/// packed MSB first; Adam7 passes when `interlaced`.
fn scanlines(
    w: usize,
    h: usize,
    bits: usize,
    interlaced: bool,
    px: impl Fn(usize, usize) -> u64,
) -> Vec<u8> {
    let passes: Vec<(usize, usize, usize, usize)> = if interlaced {
        vec![
            (0, 0, 8, 8),
            (4, 0, 8, 8),
            (0, 4, 4, 8),
            (2, 0, 4, 4),
            (0, 2, 2, 4),
            (1, 0, 2, 2),
            (0, 1, 1, 2),
        ]
    } else {
        vec![(0, 0, 1, 1)]
    };
    let mut raw = Vec::new();
    for (x0, y0, dx, dy) in passes {
        let xs: Vec<usize> = (x0..w).step_by(dx).collect();
        if xs.is_empty() {
            continue;
        }
        for y in (y0..h).step_by(dy) {
            raw.push(0);
            let mut acc = 0u128;
            let mut nbits = 0;
            let mut row = Vec::new();
            for &x in &xs {
                acc = (acc << bits) | px(x, y) as u128;
                nbits += bits;
                while nbits >= 8 {
                    row.push((acc >> (nbits - 8)) as u8);
                    nbits -= 8;
                    acc &= (1u128 << nbits) - 1;
                }
            }
            if nbits > 0 {
                row.push((acc << (8 - nbits)) as u8);
            }
            raw.extend(row);
        }
    }
    raw
}

fn ktx2_rgb32f_seed() -> Vec<u8> {
    // A 2² RGB32F cube with 2 levels, laid out by hand: the reader's third format.
    let levels = [2usize, 1];
    let mut header = vec![
        0xAB, 0x4B, 0x54, 0x58, 0x20, 0x32, 0x30, 0xBB, 0x0D, 0x0A, 0x1A, 0x0A,
    ];
    for v in [106u32, 4, 2, 2, 0, 0, 6, 2, 0, 0, 0, 0, 0] {
        header.extend(v.to_le_bytes());
    }
    header.extend(0u64.to_le_bytes());
    header.extend(0u64.to_le_bytes());
    let mut data = Vec::new();
    let mut index = Vec::new();
    let data_start = header.len() + 24 * levels.len();
    for (l, &s) in levels.iter().enumerate() {
        let off = data_start + data.len();
        let bytes: Vec<u8> = (0..s * s * 6 * 3)
            .flat_map(|k| ((k + 10 * l) as f32 * 0.125).to_le_bytes())
            .collect();
        index.extend((off as u64).to_le_bytes());
        index.extend((bytes.len() as u64).to_le_bytes());
        index.extend((bytes.len() as u64).to_le_bytes());
        data.extend(bytes);
    }
    [header, index, data].concat()
}

fn cube_chain(size: usize, min: usize) -> CubeMips {
    let mut base = Cubemap::new(size);
    for (f, face) in base.faces.iter_mut().enumerate() {
        for (k, v) in face.data.iter_mut().enumerate() {
            *v = ((f * 37 + k) as f32 * 0.61).sin().abs() * 4.0;
        }
    }
    CubeMips::build(base, min)
}

/// Rebuilds `fuzz/corpus/{exr,hdr,png,ktx2}/seed-*`: small valid files of every variant each
/// reader handles. Run: `cargo test -p ibl-core --test fuzz_regressions -- --ignored regenerate_seed_corpus`.
#[test]
#[ignore]
fn regenerate_seed_corpus() {
    use exr::prelude::{Blocks, Compression, Encoding, LineOrder, Vec2};
    let ws = workspace();
    let corpus = ws.join("fuzz/corpus");
    let mut files: Vec<(&str, String, Vec<u8>)> = Vec::new();

    // EXR: the studio fixture at 16×8, every compression, tiles, channel sets, the writer's own.
    let studio =
        io::read_image(&ws.join("fixtures/hdri/studio_256.exr"), ColorSpace::Linear).unwrap();
    let small = downsize(&studio, studio.width / 16);
    let rgb = ["R", "G", "B"];
    for (name, c) in [
        ("none", Compression::Uncompressed),
        ("rle", Compression::RLE),
        ("zip1", Compression::ZIP1),
        ("zip16", Compression::ZIP16),
        ("piz", Compression::PIZ),
        ("pxr24", Compression::PXR24),
        ("b44", Compression::B44),
        ("b44a", Compression::B44A),
        ("dwaa", Compression::DWAA(None)),
        ("dwab", Compression::DWAB(None)),
    ] {
        let enc = Encoding {
            compression: c,
            blocks: Blocks::ScanLines,
            line_order: LineOrder::Increasing,
        };
        files.push((
            "exr",
            format!("seed-{name}-half.exr"),
            exr_seed(&small, &rgb, true, enc),
        ));
    }
    let zip = Encoding {
        compression: Compression::ZIP16,
        blocks: Blocks::ScanLines,
        line_order: LineOrder::Increasing,
    };
    files.push((
        "exr",
        "seed-zip16-float.exr".into(),
        exr_seed(&small, &rgb, false, zip),
    ));
    files.push((
        "exr",
        "seed-rgba-layer-names.exr".into(),
        exr_seed(
            &small,
            &["diffuse.R", "diffuse.G", "diffuse.B", "diffuse.A"],
            true,
            zip,
        ),
    ));
    files.push((
        "exr",
        "seed-grey-y.exr".into(),
        exr_seed(&small, &["Y"], true, Encoding::UNCOMPRESSED),
    ));
    files.push(("exr", "seed-u32-single.exr".into(), exr_u32_seed()));
    let tiled = Encoding {
        compression: Compression::RLE,
        blocks: Blocks::Tiles(Vec2(8, 4)),
        line_order: LineOrder::Decreasing,
    };
    files.push((
        "exr",
        "seed-tiled-rle.exr".into(),
        exr_seed(&small, &rgb, true, tiled),
    ));
    for (name, depth) in [("f32", FloatDepth::F32), ("f16", FloatDepth::F16)] {
        let opts = WriteOptions {
            float: depth,
            ..Default::default()
        };
        files.push((
            "exr",
            format!("seed-ibl-writer-{name}.exr"),
            io::encode_image(Path::new("x.exr"), &small, &opts).unwrap(),
        ));
    }

    // HDR: the studio .hdr fixture at 16×8 (run-length encoded), a flat 4×2, a hand-written one.
    let studio_hdr =
        io::read_image(&ws.join("fixtures/hdri/studio_256.hdr"), ColorSpace::Linear).unwrap();
    let small_hdr = downsize(&studio_hdr, studio_hdr.width / 16);
    files.push((
        "hdr",
        "seed-rle-16x8.hdr".into(),
        io::encode_image(Path::new("x.hdr"), &small_hdr, &WriteOptions::default()).unwrap(),
    ));
    let tiny = downsize(&studio_hdr, studio_hdr.width / 4);
    let tiny = Image::from_data(4, 2, 3, tiny.data[..4 * 2 * 3].to_vec()).unwrap();
    files.push((
        "hdr",
        "seed-flat-4x2.hdr".into(),
        io::encode_image(Path::new("x.hdr"), &tiny, &WriteOptions::default()).unwrap(),
    ));
    let mut hand =
        b"#?RADIANCE\n# made by hand\nFORMAT=32-bit_rle_rgbe\nEXPOSURE=1.0\nGAMMA=1.0\n\n-Y 2 +X 3\n"
            .to_vec();
    for k in 0..6u8 {
        hand.extend([100 + k, 50, 10 * k, 128 + k]);
    }
    files.push(("hdr", "seed-handmade-3x2.hdr".into(), hand));

    // PNG: every channel count at 8 and 16 bits (the writer's), palette with transparency,
    // 1/2/4-bit grey, Adam7 interlacing, and JPEG (reached by format sniffing).
    let normals = io::read_image(
        &ws.join("fixtures/normals/0008_128.png"),
        ColorSpace::Linear,
    )
    .unwrap();
    let n8 = downsize(&normals, normals.width / 8);
    for ch in 1..=4 {
        for bits in [8u8, 16] {
            let img = n8.to_channels(ch);
            let opts = WriteOptions {
                png_bits: bits,
                ..Default::default()
            };
            files.push((
                "png",
                format!("seed-{ch}ch-{bits}bit.png"),
                io::encode_image(Path::new("x.png"), &img, &opts).unwrap(),
            ));
        }
    }
    let palette: Vec<u8> = (0..4u8).flat_map(|k| [k * 60, 255 - k * 60, 128]).collect();
    let trns = vec![255u8, 128, 0];
    files.push((
        "png",
        "seed-palette-2bit-trns.png".into(),
        png_seed(
            5,
            3,
            2,
            3,
            0,
            &[(b"PLTE", palette), (b"tRNS", trns)],
            &scanlines(5, 3, 2, false, |x, y| ((x + y) % 4) as u64),
        ),
    ));
    for bits in [1u8, 2, 4] {
        let raw = scanlines(7, 3, bits as usize, false, |x, y| {
            ((x * 3 + y) % (1 << bits)) as u64
        });
        files.push((
            "png",
            format!("seed-grey-{bits}bit.png"),
            png_seed(
                7,
                3,
                bits,
                0,
                0,
                &[(b"gAMA", 45455u32.to_be_bytes().to_vec())],
                &raw,
            ),
        ));
    }
    let raw = scanlines(9, 9, 24, true, |x, y| {
        ((x * 28) << 16 | (y * 28) << 8 | 99) as u64
    });
    files.push((
        "png",
        "seed-adam7-rgb.png".into(),
        png_seed(9, 9, 8, 2, 1, &[], &raw),
    ));
    for (name, ch) in [("rgb", 3usize), ("grey", 1)] {
        let img = n8.to_channels(ch);
        let bytes: Vec<u8> = img
            .data
            .iter()
            .map(|v| (v.clamp(0.0, 1.0) * 255.0) as u8)
            .collect();
        let color = if ch == 3 {
            image::ExtendedColorType::Rgb8
        } else {
            image::ExtendedColorType::L8
        };
        let mut out = Vec::new();
        use image::ImageEncoder;
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 60)
            .write_image(&bytes, 8, 8, color)
            .unwrap();
        files.push(("png", format!("seed-jpeg-{name}.jpg"), out));
    }

    // KTX2: the writer's chains (half and float, several levels, 1² alone) and RGB32F by hand.
    files.push((
        "ktx2",
        "seed-f16-4-levels3.ktx2".into(),
        ktx2::encode_cube(&cube_chain(4, 1), FloatDepth::F16),
    ));
    files.push((
        "ktx2",
        "seed-f32-4-levels2.ktx2".into(),
        ktx2::encode_cube(&cube_chain(4, 2), FloatDepth::F32),
    ));
    files.push((
        "ktx2",
        "seed-f16-1.ktx2".into(),
        ktx2::encode_cube(&cube_chain(1, 1), FloatDepth::F16),
    ));
    files.push((
        "ktx2",
        "seed-rgb32f-2-levels2.ktx2".into(),
        ktx2_rgb32f_seed(),
    ));

    // The packed and block formats in every container (zstd: supercompressed KTX2).
    use ibl_core::io::format::{Bc6hQuality, PixelFormat};
    use ibl_core::io::{dds, ktx1, texture};
    for format in PixelFormat::ALL {
        let (p, _) = texture::encode_chain(&cube_chain(4, 1), format, Bc6hQuality::Fast);
        let n = format.name();
        files.push((
            "zstd",
            format!("seed-{n}-4-levels3.ktx2"),
            ktx2::encode(&p, Some(3), &[]).unwrap(),
        ));
        files.push(("dds", format!("seed-{n}-4-levels3.dds"), dds::encode(&p)));
        let sh = [("sh".to_string(), b"0.5 0.25 0.125\n".to_vec())];
        files.push((
            "ktx1",
            format!("seed-{n}-4-levels3.ktx"),
            ktx1::encode(&p, &sh),
        ));
        if format != PixelFormat::Rgba32f {
            files.push((
                "ktx2",
                format!("seed-{n}-4-levels3.ktx2"),
                ktx2::encode(&p, None, &[]).unwrap(),
            ));
        }
    }

    for t in IMAGE_TARGETS {
        let dir = corpus.join(t);
        std::fs::create_dir_all(&dir).unwrap();
        for old in files_in(&dir) {
            if old
                .file_name()
                .unwrap()
                .to_string_lossy()
                .starts_with("seed-")
            {
                std::fs::remove_file(old).unwrap();
            }
        }
    }
    let mut total = 0;
    for (t, name, bytes) in &files {
        assert!(bytes.len() < 20_000, "{name}: {} bytes", bytes.len());
        total += bytes.len();
        std::fs::write(corpus.join(t).join(name), bytes).unwrap();
        eprintln!("{t}/{name}: {} bytes", bytes.len());
    }
    eprintln!("{} seeds, {total} bytes", files.len());
}
