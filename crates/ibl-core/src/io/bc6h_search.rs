//! BC6H_UF16 block search in the sidecar's own error metric: every mode of the D3D11 table
//! (1–10: two regions, 3-bit indices, one of 32 partitions; 11–14: one region, 4-bit
//! indices), for the two-region modes every one of the 32 partitions, endpoints searched in
//! the quantized integers the block stores against the palette the decoder computes from them
//! (quantisation-aware: unquantize, interpolate, × 31/64 exactly as decoded), each texel's
//! index chosen exactly; and the block writer for every mode, checked bit for bit against the
//! independent decoder (`bcdec_rs`, a port of bcdec) in the tests.
//!
//! Sources: Microsoft, "BC6H Format" (Direct3D 11 functional specification: the mode table,
//! the bit layouts, `unquantize`, `finish_unquantize`, the partition and anchor tables), the
//! same tables as `bcdec_rs` 0.2.1 `bc6h_half` reads them (the layouts transcribed from its
//! reader, the palette arithmetic from the spec's formulas): every layout below is checked
//! against `bcdec` bit for bit. No erratum found in either for the unsigned modes; the
//! searched blocks also decode alike in texture2ddecoder (PyPI, AssetStudio's decoders),
//! except where that one saturates a channel a hand decode from the spec does not
//! (`docs/notes/speed-bc6h.md`).

// Index loops over texels, channels, regions and ends read closer to the format's tables.
#![allow(clippy::needless_range_loop)]

/// One block's texels (up to 16; padding texels repeat the edge) with their metric weights
/// 1 / max(m, eps) (0 for padding: never sampled, never scored).
#[derive(Debug)]
pub(crate) struct BlockTexels {
    /// RGB per texel, row-major (texel `4·row + column`), clamped at 0.
    pub v: [[f32; 3]; 16],
    /// The metric's weight of each texel.
    pub weight: [f64; 16],
}

/// One BC6H_UF16 mode (D3D11 "BC6H Format", table of modes; `bcdec` `ACTUAL_BITS_COUNT`).
struct Mode {
    /// The mode's number in the D3D11 table (1–14).
    number: u8,
    /// The mode field's value as stored (bits read low first) and its length (2 or 5).
    field: u32,
    field_bits: u32,
    /// Endpoint precision in bits.
    p: u32,
    /// Bits of the stored second endpoints (all but the first), per channel; equal to `p`
    /// when they are stored as they are (modes 10 and 11), else signed deltas from the
    /// first endpoint.
    d: [u32; 3],
    /// Regions: 2 (3-bit indices, a partition) or 1 (4-bit indices).
    regions: usize,
    /// Bit layout of the endpoints after the mode field (two-region modes; the one-region
    /// layouts are regular and written by [`pack`] directly): tokens `<channel><endpoint>
    /// <first bit>[:<count>]`, endpoint w, x (region 0) and y, z (region 1), in stored order
    /// (D3D11 table of bit fields per mode, as `bcdec` reads them).
    layout: &'static str,
}

const fn two(
    number: u8,
    field: u32,
    field_bits: u32,
    p: u32,
    d: [u32; 3],
    layout: &'static str,
) -> Mode {
    Mode {
        number,
        field,
        field_bits,
        p,
        d,
        regions: 2,
        layout,
    }
}

const fn one(number: u8, field: u32, p: u32, d: u32) -> Mode {
    Mode {
        number,
        field,
        field_bits: 5,
        p,
        d: [d; 3],
        regions: 1,
        layout: "",
    }
}

/// Every BC6H_UF16 mode, in the D3D11 table's order.
const MODES: [Mode; 14] = [
    two(1, 0b00, 2, 10, [5, 5, 5], "gy4 by4 bz4 rw0:10 gw0:10 bw0:10 rx0:5 gz4 gy0:4 gx0:5 bz0 gz0:4 bx0:5 bz1 by0:4 ry0:5 bz2 rz0:5 bz3"),
    two(2, 0b01, 2, 7, [6, 6, 6], "gy5 gz4 gz5 rw0:7 bz0 bz1 by4 gw0:7 by5 bz2 gy4 bw0:7 bz3 bz5 bz4 rx0:6 gy0:4 gx0:6 gz0:4 bx0:6 by0:4 ry0:6 rz0:6"),
    two(3, 0b00010, 5, 11, [5, 4, 4], "rw0:10 gw0:10 bw0:10 rx0:5 rw10 gy0:4 gx0:4 gw10 bz0 gz0:4 bx0:4 bw10 bz1 by0:4 ry0:5 bz2 rz0:5 bz3"),
    two(4, 0b00110, 5, 11, [4, 5, 4], "rw0:10 gw0:10 bw0:10 rx0:4 rw10 gz4 gy0:4 gx0:5 gw10 gz0:4 bx0:4 bw10 bz1 by0:4 ry0:4 bz0 bz2 rz0:4 gy4 bz3"),
    two(5, 0b01010, 5, 11, [4, 4, 5], "rw0:10 gw0:10 bw0:10 rx0:4 rw10 by4 gy0:4 gx0:4 gw10 bz0 gz0:4 bx0:5 bw10 by0:4 ry0:4 bz1 bz2 rz0:4 bz4 bz3"),
    two(6, 0b01110, 5, 9, [5, 5, 5], "rw0:9 by4 gw0:9 gy4 bw0:9 bz4 rx0:5 gz4 gy0:4 gx0:5 bz0 gz0:4 bx0:5 bz1 by0:4 ry0:5 bz2 rz0:5 bz3"),
    two(7, 0b10010, 5, 8, [6, 5, 5], "rw0:8 gz4 by4 gw0:8 bz2 gy4 bw0:8 bz3 bz4 rx0:6 gy0:4 gx0:5 bz0 gz0:4 bx0:5 bz1 by0:4 ry0:6 rz0:6"),
    two(8, 0b10110, 5, 8, [5, 6, 5], "rw0:8 bz0 by4 gw0:8 gy5 gy4 bw0:8 gz5 bz4 rx0:5 gz4 gy0:4 gx0:6 gz0:4 bx0:5 bz1 by0:4 ry0:5 bz2 rz0:5 bz3"),
    two(9, 0b11010, 5, 8, [5, 5, 6], "rw0:8 bz1 by4 gw0:8 by5 gy4 bw0:8 bz5 bz4 rx0:5 gz4 gy0:4 gx0:5 bz0 gz0:4 bx0:6 by0:4 ry0:5 bz2 rz0:5 bz3"),
    two(10, 0b11110, 5, 6, [6, 6, 6], "rw0:6 gz4 bz0 bz1 by4 gw0:6 gy5 by5 bz2 gy4 bw0:6 gz5 bz3 bz5 bz4 rx0:6 gy0:4 gx0:6 gz0:4 bx0:6 by0:4 ry0:6 rz0:6"),
    one(11, 0b00011, 10, 10),
    one(12, 0b00111, 11, 9),
    one(13, 0b01011, 12, 8),
    one(14, 0b01111, 16, 4),
];

/// The 32 two-region partitions: bit `k` set when texel `k` (row-major) is in region 1
/// (D3D11 "BC6H Format" partition table; the BC7 two-subset shapes 0–31; `bcdec`
/// `PARTITION_SETS`, which the packing test reads back).
const PARTITIONS: [u16; 32] = [
    0xCCCC, 0x8888, 0xEEEE, 0xECC8, 0xC880, 0xFEEC, 0xFEC8, 0xEC80, 0xC800, 0xFFEC, 0xFE80, 0xE800,
    0xFFE8, 0xFF00, 0xFFF0, 0xF000, 0xF710, 0x008E, 0x7100, 0x08CE, 0x008C, 0x7310, 0x3100, 0x8CCE,
    0x088C, 0x3110, 0x6666, 0x366C, 0x17E8, 0x0FF0, 0x718E, 0x399C,
];

/// The anchor (fix-up) texel of region 1 per partition: its index is stored with one bit
/// less, its top bit implied 0 (region 0's anchor is texel 0).
const ANCHOR2: [usize; 32] = [
    15, 15, 15, 15, 15, 15, 15, 15, 15, 15, 15, 15, 15, 15, 15, 15, 15, 2, 8, 2, 2, 8, 8, 15, 2, 8,
    2, 2, 8, 8, 2, 2,
];

/// The 3-bit index weights (D3D11 spec; `bcdec` `a_weight3`), symmetric: `W3[7 - i] = 64 - W3[i]`.
const W3: [i32; 8] = [0, 9, 18, 27, 37, 46, 55, 64];

/// The 4-bit index weights (D3D11 spec; `bcdec` `a_weight4`), symmetric:
/// `W4[15 - i] = 64 - W4[i]`.
const W4: [i32; 16] = [0, 4, 9, 13, 17, 21, 26, 30, 34, 38, 43, 47, 51, 55, 60, 64];

/// BC6H unsigned unquantization of a `bits`-bit endpoint to 16 bits (D3D11 spec
/// `unquantize`; the same in `bcdec`).
fn unquantize(q: i32, bits: u32) -> i32 {
    if bits >= 15 {
        q
    } else if q == 0 {
        0
    } else if q == (1 << bits) - 1 {
        0xFFFF
    } else {
        ((q << 16) + 0x8000) >> bits
    }
}

/// The decoded value of weight `w` between unquantized endpoints `a` and `b`: the
/// interpolation, the unsigned finish (× 31/64) to half-float bits, as f32.
fn palette_value(a: i32, b: i32, w: i32) -> f32 {
    let v = (a * (64 - w) + b * w + 32) >> 6;
    half::f16::from_bits(((v * 31) >> 6) as u16).to_f32()
}

/// The quantized endpoint nearest a 16-bit unquantized target at `p` bits.
fn quantize(unq: f64, p: u32) -> i32 {
    let top = (1i32 << p) - 1;
    ((unq * (1u64 << p) as f64 / 65536.0 - 0.5).round() as i32).clamp(0, top)
}

/// A candidate block: mode (index into [`MODES`]), partition (two-region modes), and the
/// quantized endpoints `e[region][end][channel]` as decoded (before any swap [`pack`] makes
/// for the anchors).
#[derive(Clone, Copy, Debug)]
struct Cand {
    mode: usize,
    part: usize,
    e: [[[i32; 3]; 2]; 2],
}

impl Cand {
    fn mode(&self) -> &'static Mode {
        &MODES[self.mode]
    }

    /// Which region texel `k` is in.
    fn region(&self, k: usize) -> usize {
        if self.mode().regions == 1 {
            0
        } else {
            ((PARTITIONS[self.part] >> k) & 1) as usize
        }
    }

    /// The anchor texel of region `r`.
    fn anchor(&self, r: usize) -> usize {
        if r == 0 {
            0
        } else {
            ANCHOR2[self.part]
        }
    }

    /// Whether the block can be stored with region 0's endpoints in this order (`swap0`:
    /// swapped, as [`pack`] does when the anchor texel's index has its top bit set): every
    /// endpoint in range and every stored delta from the first endpoint within its bits.
    fn storable(&self, swap0: bool) -> bool {
        let m = self.mode();
        let top = (1 << m.p) - 1;
        let base = self.e[0][swap0 as usize];
        for r in 0..m.regions {
            for end in 0..2 {
                for c in 0..3 {
                    let v = self.e[r][end][c];
                    if !(0..=top).contains(&v) {
                        return false;
                    }
                    let d = m.d[c];
                    if d != m.p {
                        let delta = v - base[c];
                        if !(-(1 << (d - 1))..(1 << (d - 1))).contains(&delta) {
                            return false;
                        }
                    }
                }
            }
        }
        true
    }

    /// The decoded palette of region `r` (8 or 16 colours).
    fn palette(&self, r: usize) -> ([[f32; 3]; 16], usize) {
        let m = self.mode();
        let w: &[i32] = if m.regions == 2 { &W3 } else { &W4 };
        let mut pal = [[0.0; 3]; 16];
        for c in 0..3 {
            let (a, b) = (
                unquantize(self.e[r][0][c], m.p),
                unquantize(self.e[r][1][c], m.p),
            );
            for (i, wi) in w.iter().enumerate() {
                pal[i][c] = palette_value(a, b, *wi);
            }
        }
        (pal, w.len())
    }

    /// Region `r`'s least weighted error over its texels, each texel's best index written
    /// to `idx`; and whether the region's anchor texel took an index with its top bit set.
    fn fit_region(&self, t: &BlockTexels, r: usize, idx: &mut [u8; 16]) -> (f64, bool) {
        let (pal, n) = self.palette(r);
        let mut total = 0.0;
        for k in 0..16 {
            if self.region(k) != r {
                continue;
            }
            let (mut best, mut bi) = (f32::INFINITY, 0);
            for (i, q) in pal[..n].iter().enumerate() {
                let e =
                    (q[0] - t.v[k][0]).abs() + (q[1] - t.v[k][1]).abs() + (q[2] - t.v[k][2]).abs();
                if e < best {
                    (best, bi) = (e, i);
                }
            }
            idx[k] = bi as u8;
            total += best as f64 * t.weight[k];
        }
        (total, idx[self.anchor(r)] as usize >= n / 2)
    }

    /// The block's error and indices, `None` when it cannot be stored.
    fn fit(&self, t: &BlockTexels) -> Option<(f64, [u8; 16])> {
        let mut idx = [0u8; 16];
        let (mut total, mut swap0) = (0.0, false);
        for r in 0..self.mode().regions {
            let (e, high) = self.fit_region(t, r, &mut idx);
            total += e;
            if r == 0 {
                swap0 = high;
            }
        }
        self.storable(swap0).then_some((total, idx))
    }
}

/// Starting endpoints in the 16-bit unquantized space, `[region][end][channel]`.
type Starts = [[[f64; 3]; 2]; 2];

/// A little-endian bit writer over one 128-bit block.
struct Bits {
    bits: u128,
    at: u32,
}

impl Bits {
    fn put(&mut self, v: u32, n: u32) {
        if n > 0 {
            self.bits |= ((v as u128) & ((1u128 << n) - 1)) << self.at;
            self.at += n;
        }
    }
}

/// Packs the block with the texels' indices `idx`: a region whose anchor texel's index has
/// its top bit set has its endpoints swapped and its indices mirrored (the weights are
/// symmetric, so it decodes the same colours). `None` when the result cannot be stored.
fn pack(mut cand: Cand, mut idx: [u8; 16]) -> Option<[u8; 16]> {
    let m = cand.mode();
    let n = if m.regions == 2 { 8u8 } else { 16 };
    for r in 0..m.regions {
        if idx[cand.anchor(r)] >= n / 2 {
            cand.e[r].swap(0, 1);
            for k in 0..16 {
                if cand.region(k) == r {
                    idx[k] = n - 1 - idx[k];
                }
            }
        }
    }
    if !cand.storable(false) {
        return None;
    }
    // The stored endpoints: w as it is, x, y, z as it is (modes 10, 11) or as the delta
    // from w masked to its bits.
    let ends = [cand.e[0][0], cand.e[0][1], cand.e[1][0], cand.e[1][1]];
    let stored = |end: usize, c: usize| -> u32 {
        let v = ends[end][c];
        if end == 0 || m.d[c] == m.p {
            v as u32
        } else {
            ((v - ends[0][c]) as u32) & ((1 << m.d[c]) - 1)
        }
    };
    let mut b = Bits { bits: 0, at: 0 };
    b.put(m.field, m.field_bits);
    if m.regions == 2 {
        for tok in m.layout.split(' ') {
            let tb = tok.as_bytes();
            let c = match tb[0] {
                b'r' => 0,
                b'g' => 1,
                _ => 2,
            };
            let end = (tb[1] - b'w') as usize;
            let (lo, count) = match tok[2..].split_once(':') {
                Some((l, n)) => (l.parse::<u32>().ok()?, n.parse::<u32>().ok()?),
                None => (tok[2..].parse::<u32>().ok()?, 1),
            };
            b.put(stored(end, c) >> lo, count);
        }
        b.put(cand.part as u32, 5);
        for k in 0..16 {
            let bits = if k == 0 || k == ANCHOR2[cand.part] {
                2
            } else {
                3
            };
            b.put(idx[k] as u32, bits);
        }
    } else {
        // Modes 11–14: w's low 10 bits per channel, then per channel x's stored bits and
        // w's bits above 10 (highest first in modes 13 and 14: `bcdec` `read_bits_r`;
        // mode 12's one bit either way).
        for c in 0..3 {
            b.put(stored(0, c), 10);
        }
        for c in 0..3 {
            b.put(stored(1, c), m.d[c]);
            for bit in (10..m.p).rev() {
                b.put((ends[0][c] as u32 >> bit) & 1, 1);
            }
        }
        b.put(idx[0] as u32, 3);
        for &i in &idx[1..] {
            b.put(i as u32, 4);
        }
    }
    debug_assert_eq!(b.at, 128, "mode {}", m.number);
    Some(b.bits.to_le_bytes())
}

/// A texel's channel in the 16-bit space endpoints unquantize to (half bits × 64/31).
fn unq(v: f32) -> f64 {
    half::f16::from_f32(v.max(0.0)).to_bits() as f64 * 64.0 / 31.0
}

/// Starting endpoints (16-bit unquantized space) for a set of texels: the two ends of their
/// principal axis (power iteration on the covariance), and the two corners of their
/// bounding box (every channel rising together). `None` when the set is empty.
fn starts(t: &BlockTexels, members: &[usize]) -> Option<[[[f64; 3]; 2]; 2]> {
    let pts: Vec<[f64; 3]> = members
        .iter()
        .filter(|&&k| t.weight[k] > 0.0)
        .map(|&k| std::array::from_fn(|c| unq(t.v[k][c])))
        .collect();
    if pts.is_empty() {
        return None;
    }
    let n = pts.len() as f64;
    let mean: [f64; 3] = std::array::from_fn(|c| pts.iter().map(|p| p[c]).sum::<f64>() / n);
    let mut cov = [[0.0; 3]; 3];
    for p in &pts {
        for i in 0..3 {
            for j in 0..3 {
                cov[i][j] += (p[i] - mean[i]) * (p[j] - mean[j]);
            }
        }
    }
    // Power iteration from the widest channel's axis.
    let widest = (0..3)
        .max_by(|&a, &b| cov[a][a].total_cmp(&cov[b][b]))
        .unwrap_or(0);
    let mut axis = [0.0; 3];
    axis[widest] = 1.0;
    for _ in 0..12 {
        let next: [f64; 3] = std::array::from_fn(|i| (0..3).map(|j| cov[i][j] * axis[j]).sum());
        let len = next.iter().map(|v| v * v).sum::<f64>().sqrt();
        if len <= 0.0 {
            break;
        }
        axis = next.map(|v| v / len);
    }
    let (mut tmin, mut tmax) = (f64::INFINITY, f64::NEG_INFINITY);
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for p in &pts {
        let s: f64 = (0..3).map(|c| (p[c] - mean[c]) * axis[c]).sum();
        tmin = tmin.min(s);
        tmax = tmax.max(s);
        for c in 0..3 {
            lo[c] = lo[c].min(p[c]);
            hi[c] = hi[c].max(p[c]);
        }
    }
    let pca = [
        std::array::from_fn(|c| mean[c] + axis[c] * tmin),
        std::array::from_fn(|c| mean[c] + axis[c] * tmax),
    ];
    Some([pca, [lo, hi]])
}

/// Every endpoint but the first pulled into the mode's delta range around the first.
fn pull_in(cand: &mut Cand) {
    let m = cand.mode();
    for c in 0..3 {
        if m.d[c] != m.p {
            let (lo, hi) = (-(1 << (m.d[c] - 1)), (1 << (m.d[c] - 1)) - 1);
            let base = cand.e[0][0][c];
            for r in 0..m.regions {
                for end in 0..2 {
                    if (r, end) != (0, 0) {
                        cand.e[r][end][c] = base + (cand.e[r][end][c] - base).clamp(lo, hi);
                    }
                }
            }
        }
    }
}

/// Coordinate descent from `cand` (error `err`) on the twelve (or six) quantized endpoint
/// values and the six (three) shifts of both ends of a region's channel: steps from an
/// eighth of the widest span down to 1, each move repeated while the error falls. A move
/// re-fits only the region it changed (the regions' errors add up; storability is checked
/// whole).
fn descend(t: &BlockTexels, mut cand: Cand, mut err: f64) -> (f64, Cand) {
    let m = cand.mode();
    let mut idx = [0u8; 16];
    let mut parts = [0.0f64; 2];
    let mut high0 = false;
    for r in 0..m.regions {
        let (e, high) = cand.fit_region(t, r, &mut idx);
        parts[r] = e;
        if r == 0 {
            high0 = high;
        }
    }
    let span = cand
        .e
        .iter()
        .take(m.regions)
        .flat_map(|r| (0..3).map(move |c| (r[1][c] - r[0][c]).abs()))
        .max()
        .unwrap_or(0);
    let mut step = (span / 8).max(1);
    loop {
        let mut improved = false;
        for r in 0..m.regions {
            for c in 0..3 {
                for end in 0..3 {
                    for dir in [-1, 1] {
                        loop {
                            let mut next = cand;
                            if end < 2 {
                                next.e[r][end][c] += dir * step;
                            } else {
                                next.e[r][0][c] += dir * step;
                                next.e[r][1][c] += dir * step;
                            }
                            let (e, high) = next.fit_region(t, r, &mut idx);
                            let h0 = if r == 0 { high } else { high0 };
                            let total = if r == 0 { e + parts[1] } else { parts[0] + e };
                            if total < err && next.storable(h0) {
                                (cand, err, improved) = (next, total, true);
                                (parts[r], high0) = (e, h0);
                            } else {
                                break;
                            }
                        }
                    }
                }
            }
        }
        if !improved {
            if step == 1 {
                break;
            }
            step = (step / 2).max(1);
        }
    }
    (err, cand)
}

/// The endpoints that, for the texels' present indices, minimise the weighted squared
/// distance in the 16-bit unquantized space (per region and channel, the 2×2 normal
/// equations; weights the metric's scale of a channel there, value / max(m, eps)), quantized.
fn least_squares(t: &BlockTexels, cand: &Cand, idx: &[u8; 16]) -> Cand {
    let m = cand.mode();
    let w: &[i32] = if m.regions == 2 { &W3 } else { &W4 };
    let mut next = *cand;
    for r in 0..m.regions {
        for c in 0..3 {
            let (mut aa, mut ab, mut bb, mut au, mut bu) = (0.0, 0.0, 0.0, 0.0, 0.0);
            for k in (0..16).filter(|&k| cand.region(k) == r && t.weight[k] > 0.0) {
                let om = (t.v[k][c] as f64 * t.weight[k]).max(1e-6);
                let f = w[idx[k] as usize] as f64 / 64.0;
                let u = unq(t.v[k][c]);
                aa += om * (1.0 - f) * (1.0 - f);
                ab += om * (1.0 - f) * f;
                bb += om * f * f;
                au += om * (1.0 - f) * u;
                bu += om * f * u;
            }
            let det = aa * bb - ab * ab;
            if det.abs() > 1e-12 * (aa * bb).max(1e-300) {
                let a = (au * bb - bu * ab) / det;
                let b = (bu * aa - au * ab) / det;
                next.e[r][0][c] = quantize(a.clamp(0.0, 65535.0), m.p);
                next.e[r][1][c] = quantize(b.clamp(0.0, 65535.0), m.p);
            }
        }
    }
    pull_in(&mut next);
    next
}

/// Least-squares rounds after the first descent (each followed by another descent).
const LSQ_ROUNDS: usize = 1;

/// The best candidate of one mode (and partition) from one start: quantized, pulled into
/// the mode's delta range, descended ([`descend`]), then alternately re-fitted by least
/// squares on its indices and descended again while that helps.
fn refine(
    t: &BlockTexels,
    mode: usize,
    part: usize,
    start: [[[f64; 3]; 2]; 2],
) -> Option<(f64, Cand)> {
    let m = &MODES[mode];
    let mut cand = Cand {
        mode,
        part,
        e: start.map(|r| r.map(|e| e.map(|u| quantize(u, m.p)))),
    };
    pull_in(&mut cand);
    let err = cand.fit(t).map(|f| f.0)?;
    let (mut err, mut cand) = descend(t, cand, err);
    for _ in 0..LSQ_ROUNDS {
        let Some((_, idx)) = cand.fit(t) else { break };
        let next = least_squares(t, &cand, &idx);
        let Some((e, _)) = next.fit(t) else { break };
        let (e, next) = descend(t, next, e);
        if e < err {
            (err, cand) = (e, next);
        } else {
            break;
        }
    }
    Some((err, cand))
}

/// How much of the search to run.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum Effort {
    /// Every mode, and for each two-region mode all 32 partitions refined.
    Exhaustive,
    /// Every one-region mode; the two-region modes on the `n` partitions whose unrefined
    /// start scores best, scored in mode 1 (10-bit endpoints) without its delta limits.
    Partitions(usize),
}

/// Searches the block's modes (and partitions) in the metric and returns the best packed
/// block with its error as the model computes it (equal to what `bcdec` decodes: tested).
/// Deterministic: a fixed candidate order, ties kept by the earlier.
pub(crate) fn search(t: &BlockTexels, effort: Effort) -> Option<(f64, [u8; 16])> {
    let mut best: Option<(f64, Cand)> = None;
    let mut keep = |found: Option<(f64, Cand)>| {
        if let Some((e, c)) = found {
            if best.as_ref().is_none_or(|b| e < b.0) {
                best = Some((e, c));
            }
        }
    };
    // One region.
    let all: Vec<usize> = (0..16).collect();
    if let Some(s) = starts(t, &all) {
        for mode in 10..14 {
            for start in s {
                keep(refine(t, mode, 0, [start, start]));
            }
        }
    }
    // Two regions: per partition, each region's starts; a partition that splits the scored
    // texels as an earlier one does (a level of 2² or 1² texels a face leaves 12 or 15
    // texels unscored) is the same search and skipped.
    let scored: u16 = (0..16).filter(|&k| t.weight[k] > 0.0).map(|k| 1 << k).sum();
    let part_starts: Vec<Option<Vec<Starts>>> = (0..32)
        .map(|part| {
            if (0..part).any(|q| PARTITIONS[q] & scored == PARTITIONS[part] & scored) {
                return None;
            }
            let members = |r: u16| -> Vec<usize> {
                (0..16)
                    .filter(|&k| (PARTITIONS[part] >> k) & 1 == r)
                    .collect()
            };
            let s0 = starts(t, &members(0));
            let s1 = starts(t, &members(1));
            match (s0, s1) {
                (Some(a), Some(b)) => Some((0..2).map(|i| [a[i], b[i]]).collect()),
                // A region without scored texels (padding only): any endpoints serve.
                (Some(a), None) => Some((0..2).map(|i| [a[i], a[i]]).collect()),
                _ => None,
            }
        })
        .collect();
    let parts: Vec<usize> = match effort {
        Effort::Exhaustive => (0..32).collect(),
        Effort::Partitions(n) => {
            let mut scored: Vec<(f64, usize)> = (0..32)
                .filter_map(|part| {
                    let s = part_starts[part].as_ref()?;
                    let e = s
                        .iter()
                        .map(|&st| {
                            let cand = Cand {
                                mode: 0,
                                part,
                                e: st.map(|r| r.map(|e| e.map(|u| quantize(u, MODES[0].p)))),
                            };
                            // Scored as if storable: the start only ranks the partitions.
                            let mut idx = [0; 16];
                            cand.fit_region(t, 0, &mut idx).0 + cand.fit_region(t, 1, &mut idx).0
                        })
                        .fold(f64::INFINITY, f64::min);
                    Some((e, part))
                })
                .collect();
            scored.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            scored.into_iter().take(n).map(|s| s.1).collect()
        }
    };
    for mode in 0..10 {
        for &part in &parts {
            if let Some(s) = &part_starts[part] {
                for &start in s {
                    keep(refine(t, mode, part, start));
                }
            }
        }
    }
    let (_, cand) = best?;
    let (e, idx) = cand.fit(t)?;
    pack(cand, idx).map(|b| (e, b))
}

/// A much wider search than [`search`], as its check: every mode and partition refined
/// from `n` more starts, each region's endpoints two of its texels picked by a fixed
/// pseudo-random sequence. Returns the least error found.
#[cfg(test)]
pub(crate) fn search_wide(t: &BlockTexels, n: usize) -> f64 {
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let mut next = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    };
    let mut best = search(t, Effort::Exhaustive).map_or(f64::INFINITY, |b| b.0);
    for mode in 0..14 {
        let m = &MODES[mode];
        for part in 0..if m.regions == 2 { 32 } else { 1 } {
            let members: Vec<Vec<usize>> = (0..m.regions)
                .map(|r| {
                    (0..16)
                        .filter(|&k| t.weight[k] > 0.0)
                        .filter(|&k| m.regions == 1 || ((PARTITIONS[part] >> k) & 1) as usize == r)
                        .collect()
                })
                .collect();
            if members.iter().any(|v| v.is_empty()) {
                continue;
            }
            for _ in 0..n {
                let mut start = [[[0.0; 3]; 2]; 2];
                for r in 0..m.regions {
                    for end in 0..2 {
                        let k = members[r][(next() % members[r].len() as u64) as usize];
                        start[r][end] = std::array::from_fn(|c| unq(t.v[k][c]));
                    }
                }
                if let Some((e, _)) = refine(t, mode, part, start) {
                    best = best.min(e);
                }
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small xorshift, so the property tests need no dependency.
    fn rng(seed: &mut u64) -> u64 {
        *seed ^= *seed << 13;
        *seed ^= *seed >> 7;
        *seed ^= *seed << 17;
        *seed
    }

    /// A random storable candidate of `mode` and random indices.
    /// `narrow`: every endpoint within 2^(p−4) of the first (a block of modest range).
    fn random_block(mode: usize, narrow: bool, seed: &mut u64) -> (Cand, [u8; 16]) {
        let m = &MODES[mode];
        loop {
            let base: [i32; 3] = std::array::from_fn(|_| (rng(seed) % (1 << m.p)) as i32);
            let mut e = [[base; 2]; 2];
            for r in 0..m.regions {
                for end in 0..2 {
                    for c in 0..3 {
                        if (r, end) == (0, 0) {
                            continue;
                        }
                        e[r][end][c] = if m.d[c] == m.p && !narrow {
                            (rng(seed) % (1 << m.p)) as i32
                        } else {
                            let bits = if narrow {
                                (m.d[c] - 1).min(m.p - 4)
                            } else {
                                m.d[c] - 1
                            };
                            let span = 1i64 << bits;
                            (base[c] as i64 + (rng(seed) % (2 * span as u64)) as i64 - span) as i32
                        };
                    }
                }
            }
            let cand = Cand {
                mode,
                part: (rng(seed) % 32) as usize,
                e,
            };
            if !cand.storable(false) {
                continue;
            }
            let n = if m.regions == 2 { 8 } else { 16 };
            let idx: [u8; 16] = std::array::from_fn(|_| (rng(seed) % n) as u8);
            return (cand, idx);
        }
    }

    #[test]
    fn every_mode_and_partition_decodes_in_bcdec_as_the_model_says() {
        // The layout of every mode, partition and anchor checked bit for bit against the
        // independent decoder: random storable endpoints and indices, packed, decoded by
        // bcdec, equal texel for texel to the palette entry the search scores.
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        for mode in 0..MODES.len() {
            let mut tried = 0;
            let mut parts = [false; 32];
            while tried < 400 {
                let (cand, idx) = random_block(mode, false, &mut seed);
                // Swapping for an anchor can push a delta of −2^(d−1) out of range: None.
                let Some(block) = pack(cand, idx) else {
                    continue;
                };
                tried += 1;
                parts[cand.part] = true;
                let mut out = [0u16; 48];
                bcdec_rs::bc6h_half(&block, &mut out, 12, false);
                for k in 0..16 {
                    let (pal, _) = cand.palette(cand.region(k));
                    for c in 0..3 {
                        let got = half::f16::from_bits(out[3 * k + c]).to_f32();
                        assert_eq!(
                            got, pal[idx[k] as usize][c],
                            "mode {} partition {} texel {k} channel {c}",
                            MODES[mode].number, cand.part
                        );
                    }
                }
            }
            if MODES[mode].regions == 2 {
                assert!(
                    parts.iter().all(|&p| p),
                    "mode {}: every partition",
                    MODES[mode].number
                );
            }
        }
    }

    #[test]
    fn a_block_stored_in_any_mode_is_found_again_nearly_exactly() {
        // Texels that are the decoded colours of a random block of modest range (of each
        // mode): the original is one of the blocks the search could return, so what it
        // returns must be nearly exact.
        let mut seed = 12345u64;
        for mode in 0..MODES.len() {
            let (cand, idx) = loop {
                let (c, i) = random_block(mode, true, &mut seed);
                // Colours of a plausible range: endpoints not near the half-float top.
                if let Some(b) = pack(c, i) {
                    let mut out = [0u16; 48];
                    bcdec_rs::bc6h_half(&b, &mut out, 12, false);
                    let vals: Vec<f32> = out
                        .iter()
                        .map(|&h| half::f16::from_bits(h).to_f32())
                        .collect();
                    if vals.iter().all(|v| v.is_finite() && *v < 6e4) {
                        break (c, i);
                    }
                }
            };
            let mut t = BlockTexels {
                v: [[0.0; 3]; 16],
                weight: [0.0; 16],
            };
            for k in 0..16 {
                let (pal, _) = cand.palette(cand.region(k));
                t.v[k] = pal[idx[k] as usize];
                let m = t.v[k][0].max(t.v[k][1]).max(t.v[k][2]) as f64;
                t.weight[k] = 1.0 / m.max(1e-3);
            }
            let (e, block) = search(&t, Effort::Exhaustive).expect("a block");
            let mean = e / 48.0;
            assert!(mean < 0.01, "mode {}: mean {mean}", MODES[mode].number);
            // And what was packed decodes in bcdec to the error the model computed.
            let mut out = [0u16; 48];
            bcdec_rs::bc6h_half(&block, &mut out, 12, false);
            let decoded: f64 = (0..48)
                .map(|i| {
                    let v = half::f16::from_bits(out[i]).to_f32();
                    (v - t.v[i / 3][i % 3]).abs() as f64 * t.weight[i / 3]
                })
                .sum();
            assert!((decoded - e).abs() <= 1e-9 * e.max(1.0), "{decoded} vs {e}");
        }
    }

    /// A smooth block with noise, as a rough level's face has: a colour in [0.05, 20], each
    /// channel's gradient across the block up to ±60%, 15% noise.
    fn smooth_block(seed: &mut u64) -> BlockTexels {
        let mut u = || (rng(seed) % 10_000) as f32 / 10_000.0;
        let base: [f32; 3] = std::array::from_fn(|_| 0.05 * 400f32.powf(u()));
        let gx: [f32; 3] = std::array::from_fn(|_| 1.2 * u() - 0.6);
        let gy: [f32; 3] = std::array::from_fn(|_| 1.2 * u() - 0.6);
        let mut t = BlockTexels {
            v: [[0.0; 3]; 16],
            weight: [0.0; 16],
        };
        for k in 0..16 {
            let (x, y) = ((k % 4) as f32 / 3.0, (k / 4) as f32 / 3.0);
            for c in 0..3 {
                t.v[k][c] = base[c] * (1.0 + gx[c] * x + gy[c] * y) * (0.85 + 0.3 * u());
            }
            let m = t.v[k][0].max(t.v[k][1]).max(t.v[k][2]) as f64;
            t.weight[k] = 1.0 / m.max(1e-3);
        }
        t
    }

    #[test]
    fn the_search_is_within_a_few_percent_of_a_search_with_many_more_starts() {
        // Near-optimality, measured: 4 more starts per mode and partition (each region's
        // endpoints two of its own texels) find blocks at most a few percent better.
        let mut seed = 99u64;
        for b in 0..4 {
            let t = smooth_block(&mut seed);
            let found = search(&t, Effort::Exhaustive).unwrap().0;
            let wide = search_wide(&t, 4);
            assert!(wide <= found);
            assert!(found <= 1.08 * wide, "block {b}: {found} vs {wide}");
        }
    }

    #[test]
    fn ranking_partitions_loses_little_against_all_of_them() {
        let mut seed = 5u64;
        for b in 0..6 {
            let t = smooth_block(&mut seed);
            let all = search(&t, Effort::Exhaustive).unwrap().0;
            let some = search(&t, Effort::Partitions(8)).unwrap().0;
            assert!(all <= some);
            assert!(some <= 1.1 * all, "block {b}: {some} vs {all}");
        }
    }
}
