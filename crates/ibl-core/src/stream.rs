//! Streamed equirect → cube resampling: the source's rows arrive top to bottom in bands
//! and only a window of them is held. Each cube texel is computed as soon as every source row
//! its footprint can touch ([`AreaPlan::texel_rows`]) has arrived, by the very arithmetic of
//! the whole-image resample ([`crate::equirect::equirect_to_cube`]): the same bits, only the
//! rows live elsewhere.
//!
//! Memory: the window never holds more than `band + max_span` rows (`max_span` = the widest
//! texel row range, about H/n for n² faces from an H-row source), i.e. (band + max_span) × W ×
//! channels × 4 bytes, plus 4 bytes per cube texel for the texel order and the cube itself.

use crate::area::{AreaPlan, Rows, Scratch};
use crate::cube::{Cubemap, Face};
use crate::equirect::Filter;
use crate::error::Result;
use crate::image::Image;
use crate::progress::Progress;
use crate::Rgb;
use rayon::prelude::*;
use std::path::Path;

/// The row reader the streamed resample consumes; defined beside the readers that implement it
/// (`io` names no part of this module).
pub use crate::io::rows::RowSource;

/// An image in memory as a [`RowSource`] (tests, and the reference of the streamed path).
pub struct ImageRows<'a> {
    img: &'a Image,
    next: usize,
}

impl<'a> ImageRows<'a> {
    /// The rows of `img`, from the top.
    pub fn new(img: &'a Image) -> Self {
        ImageRows { img, next: 0 }
    }
}

impl RowSource for ImageRows<'_> {
    fn path(&self) -> &Path {
        Path::new("(memory)")
    }
    fn width(&self) -> usize {
        self.img.width
    }
    fn height(&self) -> usize {
        self.img.height
    }
    fn channels(&self) -> usize {
        self.img.channels
    }
    fn read_rows(&mut self, count: usize, out: &mut Vec<f32>) -> Result<()> {
        let stride = self.img.width * self.img.channels;
        let rows = &self.img.data[self.next * stride..(self.next + count) * stride];
        out.extend_from_slice(rows);
        self.next += count;
        Ok(())
    }
}

/// What a streamed resample held.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct WindowStats {
    /// Rows read per band.
    pub band: usize,
    /// The widest row range of one texel's footprint (b − a).
    pub max_span: usize,
    /// Most rows held at once (computed before the read for the window's allocation and
    /// [`window_stats`]; as measured during it in what [`equirect_to_cube_streamed`] returns).
    pub peak_rows: usize,
    /// Bytes of that window.
    pub peak_bytes: u64,
}

/// Rows read per band by default: enough texels per band to keep every core busy, few
/// enough that the band is a small part of the window (8 MB at 8k × 4k).
pub const DEFAULT_BAND: usize = 32;

/// The window's bytes for a W×H source with `channels` resampled to n² faces with `band`
/// rows per band, before reading anything (for budgets and reports): the exact peak of
/// [`equirect_to_cube_streamed`].
pub fn window_stats(w: usize, h: usize, channels: usize, n: usize, band: usize) -> WindowStats {
    let plan = AreaPlan::new(w, h, n, 0.0);
    let band = band.clamp(1, h.max(1));
    Schedule::new(&plan, band, false).stats(w * channels)
}

/// The texels of a resample ordered by the last row they read, bucketed by band.
struct Schedule {
    band: usize,
    /// Texel indices (face·n² + j·n + i), band by band.
    order: Vec<u32>,
    /// Band k's texels are `order[start[k]..start[k + 1]]`.
    start: Vec<usize>,
    /// Smallest first row of the texels of bands k.. (H when none).
    pending_lo: Vec<usize>,
    max_span: usize,
    h: usize,
}

impl Schedule {
    /// The schedule of `plan` (rotation does not move rows: latitude is kept by a turn about
    /// +Y); `with_order` false computes the bucket sizes and row bounds only.
    fn new(plan: &AreaPlan, band: usize, with_order: bool) -> Self {
        let (_, h, n) = plan.sizes();
        let bands = h.div_ceil(band);
        // Per face row: each texel's last band, and per band the smallest first row.
        let rows: Vec<(Vec<u32>, Vec<usize>, usize)> = (0..6 * n)
            .into_par_iter()
            .map(|fj| {
                let (face, j) = (Face::from_index(fj / n), fj % n);
                let mut lo = vec![usize::MAX; 0];
                let mut span = 0;
                let mut hint = [usize::MAX; 2];
                let ks = (0..n)
                    .map(|i| {
                        let (a, b) = plan.texel_rows(face, i, j, &mut hint);
                        span = span.max(b - a);
                        let k = b / band;
                        if lo.len() <= k {
                            lo.resize(k + 1, usize::MAX);
                        }
                        lo[k] = lo[k].min(a);
                        k as u32
                    })
                    .collect();
                (ks, lo, span)
            })
            .collect();
        let mut count = vec![0usize; bands + 1];
        let mut band_lo = vec![usize::MAX; bands];
        let mut max_span = 0;
        for (ks, lo, span) in &rows {
            for &k in ks {
                count[k as usize + 1] += 1;
            }
            for (k, &a) in lo.iter().enumerate() {
                band_lo[k] = band_lo[k].min(a);
            }
            max_span = max_span.max(*span);
        }
        for k in 0..bands {
            count[k + 1] += count[k];
        }
        let start = count;
        let mut pending_lo = vec![h; bands + 1];
        for k in (0..bands).rev() {
            pending_lo[k] = pending_lo[k + 1].min(band_lo[k]);
        }
        let mut order = Vec::new();
        if with_order {
            order = vec![0u32; 6 * n * n];
            let mut at = start.clone();
            for (fj, (ks, _, _)) in rows.iter().enumerate() {
                for (i, &k) in ks.iter().enumerate() {
                    order[at[k as usize]] = (fj * n + i) as u32;
                    at[k as usize] += 1;
                }
            }
        }
        Schedule {
            band,
            order,
            start,
            pending_lo,
            max_span,
            h,
        }
    }

    /// Rows band k starts from and ends at: [lo, r1).
    fn window(&self, k: usize) -> (usize, usize) {
        let r0 = k * self.band;
        let r1 = (r0 + self.band).min(self.h);
        (self.pending_lo[k].min(r0), r1)
    }

    fn stats(&self, stride: usize) -> WindowStats {
        let bands = self.h.div_ceil(self.band);
        let peak_rows = (0..bands)
            .map(|k| {
                let (lo, r1) = self.window(k);
                r1 - lo
            })
            .max()
            .unwrap_or(0);
        WindowStats {
            band: self.band,
            max_span: self.max_span,
            peak_rows,
            peak_bytes: (peak_rows * stride * 4) as u64,
        }
    }
}

/// Equirect rows from `src` → cubemap with n×n faces turned by `rotate_deg` about +Y, by
/// `filter`, reading `band` rows at a time and holding only the rows pending texels need.
/// The texels are bit-identical to [`crate::equirect::equirect_to_cube`]'s (the same
/// filter) for any band height and thread count; the window is reserved against the memory budget
/// before the first row is read.
pub fn equirect_to_cube_streamed(
    src: &mut dyn RowSource,
    n: usize,
    filter: Filter,
    rotate_deg: f32,
    band: usize,
    progress: &dyn Progress,
) -> Result<(Cubemap, WindowStats)> {
    let (cube, _, stats) = streamed(src, n, filter, false, rotate_deg, band, progress)?;
    Ok((cube, stats))
}

/// The streamed resample by `filter`, and with `mirror` (`filter` being `Area`) in the same
/// read the `Filter::Adaptive` cube (`crate::equirect::adaptive_from_area`'s bits): a bake's
/// exact-power cube and its mirror from one pass over the rows.
#[allow(clippy::too_many_arguments)]
pub(crate) fn streamed(
    src: &mut dyn RowSource,
    n: usize,
    filter: Filter,
    mirror: bool,
    rotate_deg: f32,
    band: usize,
    progress: &dyn Progress,
) -> Result<(Cubemap, Option<Cubemap>, WindowStats)> {
    debug_assert!(!mirror || filter == Filter::Area);
    let (w, h, ch) = (src.width(), src.height(), src.channels());
    let stride = w * ch;
    let plan = AreaPlan::new(w, h, n, (rotate_deg as f64).to_radians());
    let band = band.clamp(1, h.max(1));
    let sched = Schedule::new(&plan, band, true);
    let mut stats = sched.stats(stride);
    let path = src.path().to_path_buf();
    let _budget = crate::io::budget::reserve(
        &path,
        &format!(
            "a streamed read of a {w}x{h} image ({} rows at a time)",
            stats.peak_rows
        ),
        stats.peak_bytes,
    )?;
    let mut window: Vec<f32> = Vec::new();
    window
        .try_reserve_exact(stats.peak_rows * stride)
        .map_err(|_| crate::io::budget::out_of_memory(&path, stats.peak_bytes))?;
    let mut cube = Cubemap::new(n);
    let mut mirror_cube = mirror.then(|| Cubemap::new(n));
    progress.start("texels", (6 * n * n) as u64);
    let mut lo = 0usize;
    // Rows held at most, as measured (the tests hold it to the schedule's and to the bound).
    let mut held = 0usize;
    let mut values: Vec<(Rgb, Rgb)> = Vec::new();
    for k in 0..h.div_ceil(band) {
        let (_, r1) = sched.window(k);
        let r0 = k * band;
        src.read_rows(r1 - r0, &mut window)?;
        debug_assert_eq!(window.len(), (r1 - lo) * stride);
        held = held.max(window.len() / stride.max(1));
        let rows = Rows {
            data: &window,
            first: lo,
            rows: r1 - lo,
            channels: ch,
        };
        let texels = &sched.order[sched.start[k]..sched.start[k + 1]];
        texels
            .par_iter()
            .map_init(
                || (Scratch::default(), usize::MAX),
                |(sc, last), &t| {
                    let t = t as usize;
                    // The row searches start from the previous texel's rows only when it was
                    // the left neighbour (a band's texels jump between faces and rows).
                    if t != last.wrapping_add(1) {
                        sc.forget_rows();
                    }
                    *last = t;
                    let (face, j, i) = (Face::from_index(t / (n * n)), (t / n) % n, t % n);
                    let v = crate::equirect::resample_texel(&plan, filter, &rows, sc, face, i, j);
                    let m = if mirror {
                        plan.texel_value_with_area(v, &rows, face, i, j)
                    } else {
                        v
                    };
                    (v, m)
                },
            )
            .collect_into_vec(&mut values);
        for (&t, v) in texels.iter().zip(&values) {
            let t = t as usize;
            let (f, j, i) = (t / (n * n), (t / n) % n, t % n);
            cube.faces[f].texel_mut(i, j).copy_from_slice(&v.0);
            if let Some(m) = &mut mirror_cube {
                m.faces[f].texel_mut(i, j).copy_from_slice(&v.1);
            }
        }
        progress.inc(texels.len() as u64);
        // Rows no pending texel reads any more.
        let keep = sched.pending_lo[k + 1].min(r1);
        window.drain(..(keep - lo) * stride);
        lo = keep;
    }
    progress.finish();
    stats.peak_rows = held;
    stats.peak_bytes = (held * stride * 4) as u64;
    Ok((cube, mirror_cube, stats))
}

/// A Radiance equirect at the streaming threshold (2048×1024, what
/// [`crate::envmap::open_environment_with`] streams), written to `dir/name`: a repeating ramp
/// with a bright texel every 997 values, for the bakes' tests that a streamed input gives the
/// loaded one's bits.
#[doc(hidden)]
pub fn write_streamable_equirect(dir: &std::path::Path, name: &str) -> std::path::PathBuf {
    let (w, h) = (2048, 1024);
    let data: Vec<f32> = (0..w * h * 3)
        .map(|k| ((k * 7919) % 1009) as f32 * 0.01 + if k % 997 == 0 { 500.0 } else { 0.0 })
        .collect();
    let img = Image::from_data(w, h, 3, data).expect("2048x1024x3");
    let p = dir.join(name);
    let bytes = crate::io::encode_image(&p, &img, &crate::io::WriteOptions::default())
        .expect("a Radiance HDR encodes");
    std::fs::write(&p, bytes).expect("the test's folder is writable");
    p
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::equirect::{equirect_to_cube, Filter};
    use crate::progress::NoProgress;

    /// Random texels (xorshift) with a few suns, black runs and any channel count.
    fn random(w: usize, h: usize, ch: usize, seed: u64) -> Image {
        let mut img = Image::new(w, h, ch);
        let mut x = seed | 1;
        for (k, v) in img.data.iter_mut().enumerate() {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let r = (x >> 11) as f32 / (1u64 << 53) as f32;
            *v = match k % 89 {
                0 => 1e5 * r,
                1..=9 => 0.0,
                _ => r * 3.0,
            };
        }
        img
    }

    fn same_bits(a: &Cubemap, b: &Cubemap) -> bool {
        a.faces.iter().zip(&b.faces).all(|(x, y)| {
            x.data
                .iter()
                .zip(&y.data)
                .all(|(p, q)| p.to_bits() == q.to_bits())
        })
    }

    #[test]
    fn streamed_is_bit_identical_to_the_whole_image_resample() {
        // Odd sizes, 1 to 4 channels, faces with texels spanning many, one and a fraction of
        // a row, odd faces (a texel holding the pole), rotations, bands from 1 row to more
        // than the image.
        let cases: [(usize, usize, usize, usize, f32); 7] = [
            (64, 32, 3, 8, 0.0),
            (94, 47, 1, 7, 33.0),
            (202, 101, 4, 13, -170.0),
            (30, 15, 2, 1, 0.0),
            (30, 15, 3, 2, 90.0),
            (126, 63, 3, 31, 12.5),
            (258, 129, 3, 5, 720.0),
        ];
        for (c, &(w, h, ch, n, rot)) in cases.iter().enumerate() {
            let img = random(w, h, ch, 0x9e37_79b9 + c as u64);
            for band in [1, 2, 7, 32, 1000] {
                let mut stats = None;
                for filter in [Filter::Adaptive, Filter::Area, Filter::Bilinear] {
                    let whole = equirect_to_cube(&img, n, filter, rot, &NoProgress);
                    let (got, s) = equirect_to_cube_streamed(
                        &mut ImageRows::new(&img),
                        n,
                        filter,
                        rot,
                        band,
                        &NoProgress,
                    )
                    .unwrap();
                    assert!(
                        same_bits(&got, &whole),
                        "{w}x{h}x{ch} -> {n} rot {rot} band {band} {filter:?}: differs"
                    );
                    stats = Some(s);
                }
                let stats = stats.unwrap();
                // The stated bound, and the window is a fraction of the image where the
                // texels are small against it.
                let b = band.min(h);
                assert_eq!(stats, window_stats(w, h, ch, n, band), "held = scheduled");
                assert!(
                    stats.peak_rows <= b + stats.max_span,
                    "{w}x{h} -> {n} band {band}: {stats:?}"
                );
                if n >= 7 && band <= 7 {
                    assert!(stats.peak_rows < h / 2, "{w}x{h} -> {n}: {stats:?}");
                }
            }
        }
    }

    #[test]
    fn streamed_fixtures_are_bit_identical_and_the_window_small() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/hdri");
        for name in ["city_512.exr", "studio_256.hdr"] {
            let loaded = crate::envmap::load_environment(&root.join(name), false).unwrap();
            let crate::envmap::Environment::Equirect(img) = loaded.env else {
                panic!("{name} is an equirect")
            };
            // (128² from the 256-wide studio enlarges it: the adaptive filter's bilinear
            // reads and its blend band are streamed there too.)
            for (n, rot, band) in [(64usize, 0.0f32, 16usize), (33, 45.0, 1), (128, -90.0, 5)] {
                let whole = equirect_to_cube(&img, n, Filter::Adaptive, rot, &NoProgress);
                let (got, stats) = equirect_to_cube_streamed(
                    &mut ImageRows::new(&img),
                    n,
                    Filter::Adaptive,
                    rot,
                    band,
                    &NoProgress,
                )
                .unwrap();
                assert!(same_bits(&got, &whole), "{name} -> {n}");
                // A texel spans about (2/π)·H/n rows at a face centre, up to 0.9·H/n next
                // to the pole, plus a row each way for rounding: the window is the band
                // plus a few rows.
                let h = img.height;
                assert!(stats.max_span <= h / n + 3, "{name} -> {n}: {stats:?}");
                assert!(stats.peak_rows <= band + stats.max_span, "{stats:?}");
                eprintln!("{name} {}x{h} -> {n}²: window {stats:?}", img.width);
            }
        }
    }

    #[test]
    fn the_window_at_8k_is_a_few_megabytes() {
        // The bound stated in bench/speed.md: at 8192×4096 (RGB) into the source cubes the
        // prefilter bake makes (256² to 1024²), the window is the band plus the widest
        // texel's rows, a few MB where the image is 402 MB.
        for (n, most_rows) in [
            (256usize, 32 + 4096 / 256 + 3),
            (512, 32 + 11),
            (1024, 32 + 7),
        ] {
            let s = window_stats(8192, 4096, 3, n, DEFAULT_BAND);
            eprintln!("8192x4096 -> {n}²: {s:?}");
            assert!(s.peak_rows <= most_rows, "{n}: {s:?}");
            assert_eq!(s.peak_bytes, (s.peak_rows * 8192 * 12) as u64);
        }
    }

    #[test]
    fn window_stats_agree_with_the_read() {
        let img = random(200, 100, 3, 7);
        let (_, stats) = equirect_to_cube_streamed(
            &mut ImageRows::new(&img),
            9,
            Filter::Adaptive,
            10.0,
            4,
            &NoProgress,
        )
        .unwrap();
        assert_eq!(window_stats(200, 100, 3, 9, 4), stats);
    }

    #[test]
    fn a_source_error_mid_stream_is_returned() {
        struct Broken(usize);
        impl RowSource for Broken {
            fn path(&self) -> &Path {
                Path::new("broken.hdr")
            }
            fn width(&self) -> usize {
                64
            }
            fn height(&self) -> usize {
                32
            }
            fn channels(&self) -> usize {
                3
            }
            fn read_rows(&mut self, count: usize, out: &mut Vec<f32>) -> Result<()> {
                if self.0 + count > 20 {
                    return Err(crate::error::Error::invalid(
                        Path::new("broken.hdr"),
                        "truncated",
                    ));
                }
                self.0 += count;
                out.resize(out.len() + count * 64 * 3, 1.0);
                Ok(())
            }
        }
        let e = equirect_to_cube_streamed(&mut Broken(0), 8, Filter::Area, 0.0, 4, &NoProgress)
            .unwrap_err();
        assert_eq!(e.to_string(), "broken.hdr: truncated");
    }
}
