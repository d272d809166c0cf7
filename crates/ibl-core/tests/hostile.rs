//! Hostile inputs at the library level (the binaries' suite is `crates/irradiance/tests/
//! hostile.rs`): the JPEG scan walk against libjpeg-turbo's own files in every coding mode it
//! reads (baseline 4:2:0, 4:2:2 and 4:4:4, grey, optimised tables, restart intervals,
//! progressive with and without restarts; `fuzz/corpus/jpeg/`, made by `cjpeg` from a 67x33
//! noise image), each enlarged in its header or cut in its scan; and the header-size probe
//! agreeing with every decoder.

use ibl_core::io::{declared_size, decode_image, ColorSpace};
use std::path::{Path, PathBuf};

fn seeds(target: &str) -> Vec<(PathBuf, Vec<u8>)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fuzz/corpus")
        .join(target);
    let mut v: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "jpg"))
        .map(|p| {
            let b = std::fs::read(&p).unwrap();
            (p, b)
        })
        .collect();
    v.sort();
    v
}

/// Offset of the first SOFn marker (its length field follows).
fn sof(b: &[u8]) -> usize {
    (2..b.len() - 1)
        .find(|&k| b[k] == 0xFF && matches!(b[k + 1], 0xC0..=0xC2))
        .unwrap()
}

#[test]
fn libjpeg_files_in_every_mode_decode_whole() {
    let all = seeds("jpeg");
    assert!(all.len() >= 10, "{}", all.len());
    for (p, b) in &all {
        let img = decode_image(Path::new("a.jpg"), b, ColorSpace::Linear)
            .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        assert_eq!((img.width, img.height), (67, 33), "{}", p.display());
        assert_eq!(declared_size(b), Some((67, 33)));
    }
}

#[test]
fn a_header_larger_than_the_scan_is_refused_in_every_mode() {
    for (p, b) in seeds("jpeg") {
        let at = sof(&b);
        for (w, h) in [(67u16, 66u16), (134, 33), (67, 34), (68, 33), (134, 66)] {
            let mut x = b.clone();
            x[at + 5..at + 7].copy_from_slice(&h.to_be_bytes());
            x[at + 7..at + 9].copy_from_slice(&w.to_be_bytes());
            let e = decode_image(Path::new("a.jpg"), &x, ColorSpace::Linear);
            // 68 columns or 34 rows fit in the padding of 67x33's last MCU in some modes
            // (the same blocks): those may decode; every larger claim must not.
            let same_blocks = (w, h) == (68, 33) || (w, h) == (67, 34);
            match e {
                Ok(img) => assert!(
                    same_blocks,
                    "{} claiming {w}x{h} decoded to {}x{}",
                    p.display(),
                    img.width,
                    img.height
                ),
                Err(e) => {
                    let e = e.to_string();
                    assert!(
                        e.starts_with("a.jpg: ") && !e.contains('\n'),
                        "{}: {e}",
                        p.display()
                    );
                }
            }
        }
    }
}

#[test]
fn scan_data_cut_out_is_refused_in_every_mode() {
    for (p, b) in seeds("jpeg") {
        let progressive = p.to_string_lossy().contains("progressive");
        // The first scan's entropy-coded data: from after its SOS header to the next marker.
        let sos = (2..b.len() - 1)
            .find(|&k| b[k] == 0xFF && b[k + 1] == 0xDA)
            .unwrap();
        let start = sos + 2 + u16::from_be_bytes([b[sos + 2], b[sos + 3]]) as usize;
        let end = (start..b.len() - 1)
            .find(|&k| b[k] == 0xFF && b[k + 1] != 0 && !(0xD0..=0xD7).contains(&b[k + 1]))
            .unwrap();
        // Drop the second half of that scan (restart markers inside it included), keeping
        // every marker after it: the file still ends in EOI.
        let cut = start + (end - start) / 2;
        let mut x = b[..cut].to_vec();
        x.extend(&b[end..]);
        let r = decode_image(Path::new("a.jpg"), &x, ColorSpace::Linear);
        assert!(
            r.is_err(),
            "{} with half of its first scan cut out decoded (progressive: {progressive})",
            p.display()
        );
    }
}

/// Each scan of a file: (its entropy-coded data's start and end, Ss, Ah).
fn scans(b: &[u8]) -> Vec<(usize, usize, u8, u8)> {
    let mut out = Vec::new();
    let mut k = 2;
    while k + 3 < b.len() {
        if b[k] == 0xFF && b[k + 1] == 0xDA {
            let len = u16::from_be_bytes([b[k + 2], b[k + 3]]) as usize;
            let ns = b[k + 4] as usize;
            let (ss, ah) = (b[k + 5 + 2 * ns], b[k + 7 + 2 * ns] >> 4);
            let start = k + 2 + len;
            let end = (start..b.len() - 1)
                .find(|&j| b[j] == 0xFF && b[j + 1] != 0 && !(0xD0..=0xD7).contains(&b[j + 1]))
                .unwrap();
            out.push((start, end, ss, ah));
            k = end;
        } else {
            k += 1;
        }
    }
    out
}

/// Issue 24: every scan of libjpeg-turbo's progressive files (DC first, DC refinement, AC
/// first, AC refinement), cut short at several points with every marker after it kept (the
/// file still ends in EOI), is refused by the scan walk in one line, before decoding.
#[test]
fn every_progressive_scan_cut_short_is_refused() {
    let mut kinds = std::collections::BTreeSet::new();
    let mut progressive: Vec<_> = seeds("jpeg")
        .into_iter()
        .filter(|(p, _)| p.to_string_lossy().contains("progressive"))
        .collect();
    assert_eq!(progressive.len(), 3);
    // And a natural image (a normal map's colours, 256x128), whose refinement scans have
    // long runs and end-of-band runs: whole, it decodes.
    for name in ["progressive", "progressive-restart"] {
        let p = ibl_testkit::fixture(&format!("jpeg/normals-0003-{name}.jpg"));
        let b = std::fs::read(&p).unwrap();
        let img = decode_image(Path::new("a.jpg"), &b, ColorSpace::Linear).unwrap();
        assert_eq!((img.width, img.height), (256, 128));
        progressive.push((p, b));
    }
    for (p, b) in progressive {
        for (n, &(start, end, ss, ah)) in scans(&b).iter().enumerate() {
            let kind = match (ss > 0, ah > 0) {
                (false, false) => "DC first",
                (false, true) => "DC refinement",
                (true, false) => "AC first",
                (true, true) => "AC refinement",
            };
            kinds.insert(kind);
            let len = end - start;
            let mut keeps = vec![0, len / 4, len / 2, 3 * len / 4, len - 1];
            keeps.dedup();
            for keep in keeps {
                let mut x = b[..start + keep].to_vec();
                // A cut right after a 0xFF byte would leave half a stuffed pair.
                if x.last() == Some(&0xFF) {
                    x.pop();
                }
                x.extend(&b[end..]);
                let e = decode_image(Path::new("a.jpg"), &x, ColorSpace::Linear)
                    .err()
                    .unwrap_or_else(|| {
                        panic!(
                            "{} scan {n} ({kind}) cut to {keep} of {len} bytes decoded",
                            p.display()
                        )
                    })
                    .to_string();
                assert!(
                    e.starts_with("a.jpg: truncated or corrupt JPEG: its scan data ends")
                        && !e.contains('\n'),
                    "{} scan {n} ({kind}) cut to {keep} of {len}: {e}",
                    p.display()
                );
            }
        }
    }
    assert_eq!(kinds.len(), 4, "{kinds:?}");
}

/// A PNG whose IDAT stream stops early but which still ends in IEND (CRCs recomputed): the
/// structure check passes, the inflated rows are short, the decoder must fail.
#[test]
fn png_with_short_image_data_is_refused() {
    use ibl_core::io::{encode_image, WriteOptions};
    let mut img = ibl_core::Image::new(64, 32, 3);
    for (k, v) in img.data.iter_mut().enumerate() {
        *v = ((k * 7919) % 1000) as f32 / 1000.0;
    }
    let png = encode_image(Path::new("a.png"), &img, &WriteOptions::default()).unwrap();
    let idat = png.windows(4).position(|w| w == b"IDAT").unwrap() - 4;
    let len = u32::from_be_bytes(png[idat..idat + 4].try_into().unwrap()) as usize;
    for keep in [len / 4, len / 2, len - 8] {
        let mut b = png[..idat].to_vec();
        let mut chunk = b"IDAT".to_vec();
        chunk.extend(&png[idat + 8..idat + 8 + keep]);
        b.extend((keep as u32).to_be_bytes());
        b.extend(&chunk);
        b.extend(crc32(&chunk).to_be_bytes());
        b.extend(&png[idat + 12 + len..]); // the chunks after it, IEND included
        let e = decode_image(Path::new("a.png"), &b, ColorSpace::Linear);
        assert!(e.is_err(), "IDAT cut to {keep} of {len} bytes decoded");
    }
}

fn crc32(data: &[u8]) -> u32 {
    let mut c = 0xFFFF_FFFFu32;
    for &b in data {
        c ^= b as u32;
        for _ in 0..8 {
            c = if c & 1 != 0 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
    }
    !c
}

/// Radiance HDR run-length scan lines whose runs stop short of the width, or a file whose
/// last lines are missing: refused, never filled.
#[test]
fn hdr_with_short_scan_lines_is_refused() {
    let w = 16u16;
    let line = |runs: &[(u8, u8)]| {
        let mut l = vec![2, 2, (w >> 8) as u8, w as u8];
        for _ in 0..4 {
            for &(n, v) in runs {
                l.extend([128 + n, v]);
            }
        }
        l
    };
    let head =
        |h: usize| format!("#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y {h} +X {w}\n").into_bytes();
    let whole = line(&[(16, 100)]);
    let mut ok = head(2);
    ok.extend(&whole);
    ok.extend(&whole);
    let img = decode_image(Path::new("a.hdr"), &ok, ColorSpace::Linear).unwrap();
    assert_eq!((img.width, img.height), (16, 2));
    // Runs covering 12 of 16 texels, the next line's header read as data.
    let mut short = head(2);
    short.extend(line(&[(12, 100)]));
    short.extend(&whole);
    assert!(decode_image(Path::new("a.hdr"), &short, ColorSpace::Linear).is_err());
    // Three lines declared, two present.
    let mut missing = head(3);
    missing.extend(&whole);
    missing.extend(&whole);
    assert!(decode_image(Path::new("a.hdr"), &missing, ColorSpace::Linear).is_err());
}
