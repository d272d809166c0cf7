//! The area filter as it was before the per-column plan (commit 46d3809), kept verbatim as the
//! tests' reference: the new `area` module must give the same bits texel for texel.

use crate::cube::Face;
use crate::image::Image;
use crate::Rgb;
use std::f64::consts::PI;

/// Gauss–Legendre nodes and weights on [−1, 1] (3 points: exact for quintics; 2 points
/// leave 1e-6 of the solid angle and triple the error on a 1-pixel checker).
const GAUSS: [(f64, f64); 3] = [
    (-0.774_596_669_241_483_4, 5.0 / 9.0),
    (0.0, 8.0 / 9.0),
    (0.774_596_669_241_483_4, 5.0 / 9.0),
];

/// Per-source tables shared by every texel: cos θ at each row boundary, and the source
/// stored column-major as RGB so that a column's run of rows is contiguous in memory.
pub(crate) struct EquirectTables {
    w: usize,
    h: usize,
    /// cos(π j / H) for j = 0 … H.
    cos_row: Vec<f64>,
    /// texel (i, j) at index i·H + j.
    columns: Vec<[f32; 3]>,
}

impl EquirectTables {
    pub fn new(src: &Image) -> Self {
        let (w, h) = (src.width, src.height);
        let mut columns = vec![[0.0f32; 3]; w * h];
        for j in 0..h {
            for i in 0..w {
                columns[i * h + j] = src.rgb(i, j);
            }
        }
        EquirectTables {
            w,
            h,
            cos_row: (0..=h).map(|j| (PI * j as f64 / h as f64).cos()).collect(),
            columns,
        }
    }

    /// Row containing polar angle θ with cos θ = c: a guess from a cheap arccos, then
    /// settled exactly against the row-boundary table (cos_row[j] ≥ c > cos_row[j+1]).
    #[inline]
    fn row_of_cos(&self, c: f64) -> usize {
        let c = c.clamp(-1.0, 1.0);
        let guess = (crate::approx::acos(c) * self.h as f64 / PI) as usize;
        let mut j = guess.min(self.h - 1);
        while j + 1 < self.h && self.cos_row[j + 1] >= c {
            j += 1;
        }
        while j > 0 && self.cos_row[j] < c {
            j -= 1;
        }
        j
    }

    /// Column containing azimuth φ (radians, any range), after the rotation offset.
    #[inline]
    fn column_of_phi(&self, phi: f64) -> usize {
        let u = 0.5 + phi / (2.0 * PI);
        ((u * self.w as f64).floor() as i64).rem_euclid(self.w as i64) as usize
    }
}

/// Adds Σ_rows L(col, row)·(cos θ_lo − cos θ_hi)·scale for the polar-angle run whose cosines
/// go from `c_top` (smaller θ) down to `c_bot`, to `acc`; returns the weight added.
#[inline]
fn accumulate_run(
    tab: &EquirectTables,
    col: usize,
    c_top: f64,
    c_bot: f64,
    scale: f64,
    acc: &mut [f64; 3],
) -> f64 {
    if c_top <= c_bot {
        return 0.0;
    }
    let j0 = tab.row_of_cos(c_top);
    let j1 = tab.row_of_cos(c_bot);
    let column = &tab.columns[col * tab.h..(col + 1) * tab.h];
    let mut total = 0.0;
    for (bounds, l) in tab.cos_row[j0..=j1 + 1].windows(2).zip(&column[j0..=j1]) {
        let hi = c_top.min(bounds[0]);
        let lo = c_bot.max(bounds[1]);
        if hi <= lo {
            continue;
        }
        let w = (hi - lo) * scale;
        acc[0] += l[0] as f64 * w;
        acc[1] += l[1] as f64 * w;
        acc[2] += l[2] as f64 * w;
        total += w;
    }
    total
}

/// Horizontal frame of a side face: direction(s, t) = (P + sQ) − t·ŷ with P, Q unit (x, z).
fn side_frame(face: Face) -> ([f64; 2], [f64; 2]) {
    match face {
        Face::Px => ([1.0, 0.0], [0.0, -1.0]),
        Face::Nx => ([-1.0, 0.0], [0.0, 1.0]),
        Face::Pz => ([0.0, 1.0], [1.0, 0.0]),
        Face::Nz => ([0.0, -1.0], [-1.0, 0.0]),
        Face::Py | Face::Ny => unreachable!("polar faces have no side frame"),
    }
}

/// Mean radiance over face square [s0,s1]×[t0,t1] of the equirect source turned by
/// `rotate_rad` about +Y, and the solid angle the integration covered (equals the exact
/// solid angle of the square up to quadrature error; the tests check it).
#[allow(clippy::too_many_arguments)]
pub(crate) fn footprint_mean(
    tab: &EquirectTables,
    face: Face,
    s0: f64,
    s1: f64,
    t0: f64,
    t1: f64,
    rotate_rad: f64,
    cuts: &mut Vec<f64>,
) -> (Rgb, f64) {
    let mut acc = [0.0f64; 3];
    cuts.clear();
    let total = match face {
        Face::Py | Face::Ny => polar_face(tab, face, s0, s1, t0, t1, rotate_rad, &mut acc, cuts),
        _ => side_face(tab, face, s0, s1, t0, t1, rotate_rad, &mut acc, cuts),
    };
    let mean = if total > 0.0 {
        acc.map(|a| (a / total) as f32)
    } else {
        [0.0; 3]
    };
    (mean, total)
}

#[allow(clippy::too_many_arguments)]
fn side_face(
    tab: &EquirectTables,
    face: Face,
    s0: f64,
    s1: f64,
    t0: f64,
    t1: f64,
    rot: f64,
    acc: &mut [f64; 3],
    cuts: &mut Vec<f64>,
) -> f64 {
    let (p, q) = side_frame(face);
    // Sampling turned by −rot about +Y adds rot to the azimuth.
    let phi_of = |s: f64| (p[1] + s * q[1]).atan2(p[0] + s * q[0]) + rot;
    // Column boundaries crossed between s0 and s1: azimuth is monotonic in s on a face.
    let (f0, mut f1) = (phi_of(s0), phi_of(s1));
    while f1 - f0 > PI {
        f1 -= 2.0 * PI;
    }
    while f0 - f1 > PI {
        f1 += 2.0 * PI;
    }
    let w = tab.w as f64;
    let (x0, x1) = ((0.5 + f0 / (2.0 * PI)) * w, (0.5 + f1 / (2.0 * PI)) * w);
    cuts.push(s0);
    let (lo, hi) = if x0 < x1 { (x0, x1) } else { (x1, x0) };
    let mut k = lo.floor() + 1.0;
    while k < hi {
        // Azimuth of the boundary, then s where P + sQ points along it.
        let phi_b = 2.0 * PI * (k / w - 0.5) - rot;
        let (sn, cs) = phi_b.sin_cos();
        let s_b = (p[1] * cs - p[0] * sn) / (q[0] * sn - q[1] * cs);
        // Clamped, never dropped: every boundary steps the column index below.
        cuts.push(s_b.clamp(s0, s1));
        k += 1.0;
    }
    cuts.push(s1);
    // The boundaries come out ordered in s already, ascending or descending with x.
    let inner = cuts.len() - 1;
    if inner > 2 && cuts[1] > cuts[inner - 1] {
        cuts[1..inner].reverse();
    }
    // Columns step by one from the column at s0 in the direction x moves with s.
    let dir: i64 = if x1 >= x0 { 1 } else { -1 };
    // The column just inside s0 (x0 may sit exactly on a boundary, as it does at face edges).
    let start = if dir > 0 { x0.floor() } else { x0.ceil() - 1.0 };
    let mut col = (start as i64).rem_euclid(tab.w as i64);
    let mut total = 0.0;
    for (k, piece) in cuts.windows(2).enumerate() {
        if k > 0 {
            col = (col + dir).rem_euclid(tab.w as i64);
        }
        let (a, b) = (piece[0], piece[1]);
        if b <= a {
            continue;
        }
        let col = col as usize;
        let half = 0.5 * (b - a);
        for (x, gw) in GAUSS {
            let s = 0.5 * (a + b) + half * x;
            let big_a = 1.0 + s * s;
            // cos θ = −t / sqrt(A + t²): the top edge t0 has the smaller θ.
            let c_top = -t0 / (big_a + t0 * t0).sqrt();
            let c_bot = -t1 / (big_a + t1 * t1).sqrt();
            total += accumulate_run(tab, col, c_top, c_bot, gw * half / big_a, acc);
        }
    }
    total
}

#[allow(clippy::too_many_arguments)]
fn polar_face(
    tab: &EquirectTables,
    face: Face,
    s0: f64,
    s1: f64,
    t0: f64,
    t1: f64,
    rot: f64,
    acc: &mut [f64; 3],
    cuts: &mut Vec<f64>,
) -> f64 {
    // Face-plane coordinates (X, Z) = horizontal part of the direction: py (s, t), ny (s, −t).
    let north = face == Face::Py;
    let (x0, x1) = (s0, s1);
    let (z0, z1) = if north { (t0, t1) } else { (-t1, -t0) };
    let contains_pole = x0 <= 0.0 && x1 >= 0.0 && z0 <= 0.0 && z1 >= 0.0;
    // Angular range of the square seen from the pole, unwrapped around its centre angle.
    let (phi_lo, phi_hi) = if contains_pole {
        (-PI, PI)
    } else {
        let centre = (0.5 * (z0 + z1)).atan2(0.5 * (x0 + x1));
        let mut lo = f64::INFINITY;
        let mut hi = f64::NEG_INFINITY;
        for (x, z) in [(x0, z0), (x1, z0), (x0, z1), (x1, z1)] {
            let mut a = z.atan2(x) - centre;
            a = (a + PI).rem_euclid(2.0 * PI) - PI;
            lo = lo.min(a);
            hi = hi.max(a);
        }
        (centre + lo, centre + hi)
    };
    // The ray–square distance has kinks at the corner directions: cut there too.
    cuts.push(phi_lo);
    cuts.push(phi_hi);
    {
        for (x, z) in [(x0, z0), (x1, z0), (x0, z1), (x1, z1)] {
            let mut a = z.atan2(x);
            while a < phi_lo {
                a += 2.0 * PI;
            }
            while a > phi_hi {
                a -= 2.0 * PI;
            }
            if a > phi_lo && a < phi_hi {
                cuts.push(a);
            }
        }
    }
    // Meridians: with the rotation, column boundary k sits at azimuth 2π(k/W − 0.5) − rot.
    let w = tab.w as f64;
    let k_lo = ((0.5 + (phi_lo + rot) / (2.0 * PI)) * w).floor() + 1.0;
    let k_hi = (0.5 + (phi_hi + rot) / (2.0 * PI)) * w;
    let mut k = k_lo;
    while k < k_hi {
        cuts.push(2.0 * PI * (k / w - 0.5) - rot);
        k += 1.0;
    }
    cuts.sort_by(|a, b| a.partial_cmp(b).unwrap());
    let mut total = 0.0;
    for piece in cuts.windows(2) {
        let (a, b) = (piece[0], piece[1]);
        if b <= a {
            continue;
        }
        let col = tab.column_of_phi(0.5 * (a + b) + rot);
        let half = 0.5 * (b - a);
        for (xg, gw) in GAUSS {
            let phi = 0.5 * (a + b) + half * xg;
            let (sn, cs) = phi.sin_cos();
            // Ray–square intersection (slab method) in the face plane.
            let (mut r_in, mut r_out) = (0.0f64, f64::INFINITY);
            for (d, lo, hi) in [(cs, x0, x1), (sn, z0, z1)] {
                if d.abs() < 1e-300 {
                    if lo > 0.0 || hi < 0.0 {
                        r_out = -1.0;
                    }
                    continue;
                }
                let (ta, tb) = (lo / d, hi / d);
                r_in = r_in.max(ta.min(tb));
                r_out = r_out.min(ta.max(tb));
            }
            if r_out <= r_in {
                continue;
            }
            // cos θ' = 1/sqrt(1+ρ²) from the pole; on the south face θ = π − θ'.
            let c_near = 1.0 / (1.0 + r_in * r_in).sqrt();
            let c_far = 1.0 / (1.0 + r_out * r_out).sqrt();
            let (c_top, c_bot) = if north {
                (c_near, c_far)
            } else {
                (-c_far, -c_near)
            };
            total += accumulate_run(tab, col, c_top, c_bot, gw * half, acc);
        }
    }
    total
}
