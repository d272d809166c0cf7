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
