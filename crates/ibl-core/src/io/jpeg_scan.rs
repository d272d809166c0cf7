//! Checks that a JPEG's entropy-coded data covers every block its frame header declares,
//! without decoding a texel: zune-jpeg (strict mode included) pads a scan that ends early
//! with zero bits and returns success, so a 64x32 JPEG whose SOF is patched to 128x64 would
//! read as a 128x64 image whose missing three quarters are made up. A decoder that fills in
//! missing data has failed; this walk finds it.
//!
//! The walk follows ITU-T T.81: markers (B.1), frame and scan headers (B.2), Huffman tables
//! (B.2.4.2, C), the sequential block coding (F.1.2: a DC difference category and its bits,
//! then run/size AC symbols to EOB) and every progressive scan (G.1.2: DC first, DC
//! refinement at one bit a block, AC first with end-of-band runs, AC refinement); restart
//! intervals (B.2.4.4) reset the bit reader. An AC refinement scan (G.1.2.3) carries one
//! correction bit for each coefficient earlier scans made non-zero, so the walk keeps, per
//! block, a 64-bit mask of the coefficients the AC scans so far made non-zero (8 bytes a
//! block, reserved against the memory budget). It also refuses, before decoding, a file too
//! short for its header: a sequential block costs at least 2 bits (a DC code and an EOB code),
//! a progressive one at least 1 (its DC code in the DC first scan), so a 662-byte file cannot
//! hold the 4 million blocks of 16384².
//!
//! Bit order of a refinement block (T.81 G.1.2.3, as libjpeg `jdphuff.c` decode_mcu_AC_refine
//! reads it): the RS symbol, the new coefficient's sign bit, then a correction bit for each
//! non-zero coefficient passed on the way to it; a ZRL passes 16 zero coefficients (the
//! non-zero ones in between do not count), and an EOB run leaves a correction bit for each
//! non-zero coefficient of the rest of the band in every block it covers.

use crate::error::{Error, Result};
use std::path::Path;

/// A Huffman table: for each code length 1..=16, the first code, how many codes, and the
/// index of its first symbol (T.81 Annex C, F.2.2.3's MINCODE/MAXCODE/VALPTR).
#[derive(Clone, Default)]
struct Huffman {
    mincode: [u32; 17],
    count: [u32; 17],
    valptr: [usize; 17],
    symbols: Vec<u8>,
}

impl Huffman {
    fn new(counts: &[u8; 16], symbols: &[u8]) -> Self {
        let mut h = Huffman {
            symbols: symbols.to_vec(),
            ..Default::default()
        };
        let (mut code, mut k) = (0u32, 0usize);
        for l in 1..=16 {
            h.mincode[l] = code;
            h.count[l] = counts[l - 1] as u32;
            h.valptr[l] = k;
            code += h.count[l];
            k += h.count[l] as usize;
            code <<= 1;
        }
        h
    }
}

/// Bits of one entropy-coded segment (between markers), stuffed zeros removed, read through
/// a 64-bit accumulator kept at least 16 bits full (a Huffman code and its extra bits are at
/// most 16 each): past the segment's end it is filled with 1 bits (what encoders pad with),
/// and reading any of those counts in `over`, which the walk refuses.
struct Bits<'a> {
    data: &'a [u8],
    at: usize,
    acc: u64,
    /// Bits in `acc` not yet read.
    n: u32,
    /// How many of the lowest of those are made-up padding.
    pad: u32,
    /// Made-up bits read.
    over: u32,
}

impl<'a> Bits<'a> {
    fn new(data: &'a [u8], at: usize) -> Self {
        Bits {
            data,
            at,
            acc: 0,
            n: 0,
            pad: 0,
            over: 0,
        }
    }
    /// Next byte of the segment, or `None` at a marker or the end of the file.
    fn byte(&mut self) -> Option<u8> {
        let b = *self.data.get(self.at)?;
        if b == 0xFF {
            match self.data.get(self.at + 1) {
                Some(0x00) => {
                    self.at += 2;
                    return Some(0xFF);
                }
                _ => return None,
            }
        }
        self.at += 1;
        Some(b)
    }
    fn fill(&mut self) {
        while self.n <= 56 {
            let b = if self.pad > 0 { None } else { self.byte() };
            let b = b.unwrap_or_else(|| {
                self.pad += 8;
                0xFF
            });
            self.acc = (self.acc << 8) | b as u64;
            self.n += 8;
        }
    }
    #[inline]
    fn peek(&self, k: u32) -> u32 {
        ((self.acc >> (self.n - k)) & ((1u64 << k) - 1)) as u32
    }
    #[inline]
    fn consume(&mut self, k: u32) {
        self.n -= k;
        if self.n < self.pad {
            self.over = self.pad - self.n;
        }
    }
    fn bits(&mut self, k: u32) -> u32 {
        if k == 0 {
            return 0;
        }
        self.fill();
        let v = self.peek(k);
        self.consume(k);
        v
    }
    /// One Huffman symbol; `None` for a code no table entry has (corrupt data).
    fn decode(&mut self, h: &Huffman) -> Option<u8> {
        self.fill();
        for l in 1..=16u32 {
            let code = self.peek(l);
            let li = l as usize;
            if code.wrapping_sub(h.mincode[li]) < h.count[li] {
                self.consume(l);
                return h
                    .symbols
                    .get(h.valptr[li] + (code - h.mincode[li]) as usize)
                    .copied();
            }
        }
        None
    }
    /// Drops the rest of the current byte and skips the restart marker that must come next
    /// (T.81 B.2.4.4); false when data or padding was read past it, or no marker follows.
    fn restart(&mut self) -> bool {
        // Real bits still unread: only the current byte's padding may be left.
        if self.over > 0 || self.n - self.pad >= 8 {
            return false;
        }
        self.acc = 0;
        self.n = 0;
        self.pad = 0;
        match (self.data.get(self.at), self.data.get(self.at + 1)) {
            (Some(0xFF), Some(0xD0..=0xD7)) => {
                self.at += 2;
                true
            }
            _ => false,
        }
    }
}

#[derive(Clone, Copy, Default)]
struct Component {
    id: u8,
    h: usize,
    v: usize,
}

/// Refuses a JPEG whose scans hold fewer blocks than its frame header declares (see the
/// module comment). Files this walk does not understand are left to the decoder.
pub(crate) fn check(path: &Path, b: &[u8]) -> Result<()> {
    let bad = |why: String| Error::invalid(path, why);
    let mut at = 2usize;
    let mut dc: Vec<Huffman> = vec![Huffman::default(); 4];
    let mut ac: Vec<Huffman> = vec![Huffman::default(); 4];
    let mut comps: Vec<Component> = Vec::new();
    let (mut width, mut height, mut progressive) = (0usize, 0usize, false);
    let mut restart = 0usize;
    // Per component, per block: the AC coefficients progressive scans made non-zero so far.
    let mut nonzero: Vec<Vec<u64>> = Vec::new();
    let mut reserved = Vec::new();
    let be16 = |o: usize| -> Option<usize> {
        Some(u16::from_be_bytes([*b.get(o)?, *b.get(o + 1)?]) as usize)
    };
    loop {
        while b.get(at) == Some(&0xFF) && b.get(at + 1) == Some(&0xFF) {
            at += 1;
        }
        let (Some(0xFF), Some(&m)) = (b.get(at), b.get(at + 1)) else {
            return Ok(()); // the marker walk (`ldr::jpeg_end`) reports structure errors
        };
        if m == 0xD9 {
            return Ok(());
        }
        if m == 0x01 || (0xD0..=0xD7).contains(&m) {
            at += 2;
            continue;
        }
        let Some(len) = be16(at + 2) else {
            return Ok(());
        };
        let seg = b.get(at + 4..at + 2 + len).unwrap_or(&[]);
        match m {
            // Huffman-coded frames: baseline, extended, progressive.
            0xC0..=0xC2 if seg.len() >= 6 => {
                progressive = m == 0xC2;
                height = u16::from_be_bytes([seg[1], seg[2]]) as usize;
                width = u16::from_be_bytes([seg[3], seg[4]]) as usize;
                comps = seg[6..]
                    .chunks_exact(3)
                    .take(seg[5] as usize)
                    .map(|c| Component {
                        id: c[0],
                        h: (c[1] >> 4).max(1) as usize,
                        v: (c[1] & 15).max(1) as usize,
                    })
                    .collect();
                if comps.is_empty() || width == 0 || height == 0 {
                    return Ok(());
                }
                // At least 2 bits a sequential block (B.2 / F.1.2: a DC code and an EOB code),
                // 1 a progressive one (G.1.2.1: its DC code in the DC first scan).
                let blocks = frame_blocks(width, height, &comps);
                let room = (b.len() as u64).saturating_mul(8);
                if blocks.saturating_mul(if progressive { 1 } else { 2 }) > room {
                    return Err(bad(format!(
                        "truncated JPEG: {} bytes cannot hold the {blocks} blocks of a {width}x{height} image",
                        b.len()
                    )));
                }
                nonzero = vec![Vec::new(); comps.len()];
            }
            0xC4 => {
                let mut o = 0usize;
                while o + 17 <= seg.len() {
                    let (class, id) = (seg[o] >> 4, (seg[o] & 15) as usize);
                    let counts: [u8; 16] = seg[o + 1..o + 17].try_into().expect("16");
                    let n: usize = counts.iter().map(|&c| c as usize).sum();
                    let Some(symbols) = seg.get(o + 17..o + 17 + n) else {
                        return Ok(());
                    };
                    if id < 4 {
                        let t = Huffman::new(&counts, symbols);
                        if class == 0 {
                            dc[id] = t;
                        } else {
                            ac[id] = t;
                        }
                    }
                    o += 17 + n;
                }
            }
            0xDD if seg.len() >= 2 => restart = u16::from_be_bytes([seg[0], seg[1]]) as usize,
            0xDA => {
                let ns = *seg.first().unwrap_or(&0) as usize;
                let Some(spec) = seg.get(1..1 + 2 * ns) else {
                    return Ok(());
                };
                let tail = seg.get(1 + 2 * ns..1 + 2 * ns + 3).unwrap_or(&[0, 63, 0]);
                let (ss, se, ah) = (tail[0] as usize, tail[1] as usize, tail[2] >> 4);
                let mut scan = Vec::new();
                for s in spec.chunks_exact(2) {
                    let Some(k) = comps.iter().position(|c| c.id == s[0]) else {
                        return Ok(());
                    };
                    scan.push((k, (s[1] >> 4) as usize & 3, (s[1] & 15) as usize & 3));
                }
                at = at + 2 + len;
                // An AC scan holds one component (G.1.1.1.1); its blocks' masks, made on first use.
                let ac_band = progressive && ss > 0 && scan.len() == 1;
                if ac_band && nonzero.get(scan[0].0).is_some_and(Vec::is_empty) {
                    let k = scan[0].0;
                    let n = component_blocks(width, height, &comps, k);
                    reserved.push(super::budget::reserve(
                        path,
                        &format!("checking the scans of a {width}x{height} progressive JPEG"),
                        n.saturating_mul(8),
                    )?);
                    nonzero[k] = vec![0u64; n as usize];
                }
                // A progressive AC scan of several components is invalid: left to the decoder.
                let walkable = !comps.is_empty() && (!progressive || ss == 0 || ac_band);
                if walkable {
                    let walk = Scan {
                        comps: &comps,
                        scan: &scan,
                        width,
                        height,
                        restart,
                        progressive,
                        ss,
                        se: se.min(63),
                        dc_refine: progressive && ss == 0 && ah > 0,
                        ac_refine: progressive && ss > 0 && ah > 0,
                    };
                    let masks = if ac_band {
                        nonzero.get_mut(scan[0].0).map(Vec::as_mut_slice)
                    } else {
                        None
                    };
                    let (done, total, end) = walk.run(b, at, &dc, &ac, masks);
                    if done < total {
                        return Err(bad(format!(
                            "truncated or corrupt JPEG: its scan data ends after {done} of the {total} {} its {width}x{height} header declares",
                            if scan.len() > 1 { "MCUs" } else { "blocks" }
                        )));
                    }
                    at = end;
                }
                // Skip the rest of the entropy-coded data to the next real marker.
                while at + 1 < b.len() {
                    if b[at] == 0xFF && b[at + 1] != 0 && !(0xD0..=0xD7).contains(&b[at + 1]) {
                        break;
                    }
                    at += 1;
                }
                continue;
            }
            _ => {}
        }
        at = at + 2 + len;
    }
}

/// Blocks of every component of a frame (T.81 A.1.1: component c has ⌈X·Hc/Hmax⌉ columns).
fn frame_blocks(width: usize, height: usize, comps: &[Component]) -> u64 {
    (0..comps.len())
        .map(|k| component_blocks(width, height, comps, k))
        .sum()
}

/// Blocks of component `k`, as a scan of it alone visits them (A.2.2).
fn component_blocks(width: usize, height: usize, comps: &[Component], k: usize) -> u64 {
    let hmax = comps.iter().map(|c| c.h).max().unwrap_or(1);
    let vmax = comps.iter().map(|c| c.v).max().unwrap_or(1);
    let c = comps[k];
    let bw = (width * c.h).div_ceil(hmax).div_ceil(8) as u64;
    let bh = (height * c.v).div_ceil(vmax).div_ceil(8) as u64;
    bw * bh
}

struct Scan<'a> {
    comps: &'a [Component],
    /// (component index, DC table, AC table) of each scan component.
    scan: &'a [(usize, usize, usize)],
    width: usize,
    height: usize,
    restart: usize,
    progressive: bool,
    ss: usize,
    se: usize,
    dc_refine: bool,
    ac_refine: bool,
}

impl Scan<'_> {
    /// Walks the scan's MCUs; returns (MCUs whose bits were all in the data, MCUs declared,
    /// where the data ended).
    /// `masks`: the non-zero masks of the blocks of a one-component AC scan, in scan order.
    fn run(
        &self,
        b: &[u8],
        at: usize,
        dc: &[Huffman],
        ac: &[Huffman],
        mut masks: Option<&mut [u64]>,
    ) -> (u64, u64, usize) {
        let hmax = self.comps.iter().map(|c| c.h).max().unwrap_or(1);
        let vmax = self.comps.iter().map(|c| c.v).max().unwrap_or(1);
        // Blocks per MCU of each scan component, and the MCU count (A.2.2, A.2.3).
        let (total, per_mcu): (u64, Vec<usize>) = if self.scan.len() == 1 {
            let c = self.comps[self.scan[0].0];
            let bw = (self.width * c.h).div_ceil(hmax).div_ceil(8) as u64;
            let bh = (self.height * c.v).div_ceil(vmax).div_ceil(8) as u64;
            (bw * bh, vec![1])
        } else {
            let mx = self.width.div_ceil(8 * hmax) as u64;
            let my = self.height.div_ceil(8 * vmax) as u64;
            (
                mx * my,
                self.scan
                    .iter()
                    .map(|&(k, _, _)| self.comps[k].h * self.comps[k].v)
                    .collect(),
            )
        };
        let mut bits = Bits::new(b, at);
        let mut eobrun = 0u32;
        let mut done = 0u64;
        while done < total {
            if self.restart > 0 && done > 0 && done.is_multiple_of(self.restart as u64) {
                if !bits.restart() {
                    break;
                }
                eobrun = 0;
            }
            let mut ok = true;
            if let Some(m) = masks.as_deref_mut() {
                // One component (per_mcu is 1): block `done` of it.
                let ta = self.scan[0].2;
                let mut none = 0u64;
                let mask = m.get_mut(done as usize).unwrap_or(&mut none);
                ok = if self.ac_refine {
                    self.ac_refine_block(&mut bits, &ac[ta], &mut eobrun, mask)
                } else {
                    self.block(&mut bits, &dc[0], &ac[ta], &mut eobrun, mask)
                };
            } else {
                let mut none = 0u64;
                'mcu: for (s, &(_, td, ta)) in self.scan.iter().enumerate() {
                    for _ in 0..per_mcu[s] {
                        if !self.block(&mut bits, &dc[td], &ac[ta], &mut eobrun, &mut none) {
                            ok = false;
                            break 'mcu;
                        }
                    }
                }
            }
            if !ok || bits.over > 0 {
                break;
            }
            done += 1;
        }
        (done, total, bits.at)
    }

    /// One block's bits (F.1.2.1, F.1.2.2; G.1.2.1, G.1.2.2); false on a corrupt code. An AC
    /// first scan marks in `nonzero` the coefficients it makes non-zero.
    fn block(
        &self,
        bits: &mut Bits,
        dc: &Huffman,
        ac: &Huffman,
        eobrun: &mut u32,
        nonzero: &mut u64,
    ) -> bool {
        if !self.progressive || self.ss == 0 {
            if self.dc_refine {
                bits.bits(1);
                return true;
            }
            let Some(s) = bits.decode(dc) else {
                return false;
            };
            if s > 16 {
                return false;
            }
            bits.bits(s as u32);
            if self.progressive {
                return true;
            }
        }
        let (mut k, end) = if self.progressive {
            if *eobrun > 0 {
                *eobrun -= 1;
                return true;
            }
            (self.ss, self.se)
        } else {
            (1, 63)
        };
        while k <= end {
            let Some(rs) = bits.decode(ac) else {
                return false;
            };
            let (r, s) = ((rs >> 4) as usize, (rs & 15) as u32);
            if s == 0 {
                if r == 15 {
                    k += 16;
                    continue;
                }
                if self.progressive {
                    *eobrun = (1u32 << r) - 1;
                    if r > 0 {
                        *eobrun += bits.bits(r as u32);
                    }
                }
                return true;
            }
            k += r;
            bits.bits(s);
            if k <= 63 {
                *nonzero |= 1 << k;
            }
            k += 1;
        }
        k <= end + 1
    }

    /// One block of an AC refinement scan (G.1.2.3; libjpeg `jdphuff.c`
    /// decode_mcu_AC_refine): new coefficients of magnitude 1 (a sign bit each) placed after
    /// R zero coefficients, a correction bit for every non-zero coefficient passed on the way
    /// and, in an end-of-band run, for every non-zero coefficient of the rest of the band.
    /// False on a corrupt code (a new coefficient not of size 1, or beyond the band).
    fn ac_refine_block(
        &self,
        bits: &mut Bits,
        ac: &Huffman,
        eobrun: &mut u32,
        nonzero: &mut u64,
    ) -> bool {
        let (mut k, end) = (self.ss, self.se);
        let set = |m: u64, k: usize| (m >> k) & 1 == 1;
        if *eobrun == 0 {
            while k <= end {
                let Some(rs) = bits.decode(ac) else {
                    return false;
                };
                let (mut r, s) = ((rs >> 4) as usize, rs & 15);
                if s != 0 {
                    if s != 1 {
                        return false;
                    }
                    bits.bits(1);
                } else if r != 15 {
                    // EOBr: this block and 2^r - 1 + (r bits) more end here.
                    *eobrun = 1u32 << r;
                    if r > 0 {
                        *eobrun += bits.bits(r as u32);
                    }
                    break;
                }
                // Pass the non-zero coefficients (a correction bit each) and r zero ones.
                while k <= end {
                    if set(*nonzero, k) {
                        bits.bits(1);
                    } else {
                        if r == 0 {
                            break;
                        }
                        r -= 1;
                    }
                    k += 1;
                }
                if s != 0 {
                    if k > end {
                        return false;
                    }
                    *nonzero |= 1 << k;
                }
                k += 1;
            }
        }
        if *eobrun > 0 {
            while k <= end {
                if set(*nonzero, k) {
                    bits.bits(1);
                }
                k += 1;
            }
            *eobrun -= 1;
        }
        true
    }
}
