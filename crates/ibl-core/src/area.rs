//! Exact footprint integrals of an equirect image over cube texels: the mean radiance of the
//! piecewise-constant source over each texel, computed in closed form along one axis and by
//! Gauss–Legendre quadrature along the other, between the source's own pixel boundaries.
//!
//! On a side face (±X, ±Z) the meridians are the lines s = const and the solid angle of a
//! vertical run is closed-form: ∫ dt / (A + t²)^{3/2} over rows = (cos θ_a − cos θ_b) / A with
//! A = 1 + s². On a polar face (±Y) the meridians are rays from the face centre and the
//! parallels are circles ρ = tan θ', with ∫ ρ dρ / (1 + ρ²)^{3/2} = cos θ'_a − cos θ'_b.
//! So only one integral per column piece is numerical, and its integrand is smooth there.
//!
//! Work per texel, and why it is arranged so: on a side face the column cuts, the Gauss nodes
//! and their weights depend on the texel's column alone, so [`AreaPlan`] computes them once per
//! column of texels (n per face instead of n² times); what is left per texel is, per node, two
//! square roots for the run's ends. On a polar face the cuts are the texel's own (its corners'
//! directions and the meridians between them); the cut directions come without trigonometry
//! (corners by x/r, z/r; meridians from a table) and each node's by turning its piece's start
//! through a short series. The three nodes of a piece share its source column, so their runs
//! are summed row by row: one row search per piece end (started from the previous piece's
//! rows, so a step or two instead of an arccos) and one read of each source pixel. The source
//! is read in place, row-major (a texel row's runs walk along the same few source rows; a
//! column-major copy would double the source's memory). The terms are those of the code this
//! replaced (`area_before.rs`, the tests' reference) summed in another order, so the results
//! agree to rounding (the tests measure it), and every texel is a function of its coordinates
//! alone: the same bits for any thread count.

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

/// Below this many source pixels a texel side ([`AreaPlan::texel_value`]'s ρ) the adaptive
/// filter reads the bilinear reconstruction at the texel's centre alone.
pub(crate) const RHO_BILINEAR: f64 = 0.5;

/// From this many source pixels a texel side the adaptive filter is the footprint mean alone.
pub(crate) const RHO_AREA: f64 = 0.75;

/// b + (a − b)·w per channel: the bilinear reading `b` moved toward the footprint mean `a`.
fn blend(b: [f64; 3], a: Rgb, w: f64) -> Rgb {
    std::array::from_fn(|k| (b[k] + (a[k] as f64 - b[k]) * w) as f32)
}

/// One column piece of a side-face texel column: the source column and, per Gauss node, A =
/// 1 + s² and the node's weight gw·half/A.
#[derive(Clone, Copy, Debug)]
struct SidePiece {
    col: usize,
    big_a: [f64; 3],
    scale: [f64; 3],
}

/// The pieces of every texel column of one side face: column i's are
/// `pieces[start[i]..start[i + 1]]`.
#[derive(Default)]
struct SideColumns {
    start: Vec<usize>,
    pieces: Vec<SidePiece>,
}

/// The source rows a resample reads: rows `first .. first + rows` of a W-wide equirect with
/// `channels` channels, row-major from `data[0]` (the whole image, or the window of a streamed
/// read: only where the rows live differs, never the arithmetic).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Rows<'a> {
    pub data: &'a [f32],
    pub first: usize,
    pub rows: usize,
    pub channels: usize,
}

impl<'a> Rows<'a> {
    /// Every row of `img`.
    pub fn whole(img: &'a Image) -> Self {
        Rows {
            data: &img.data,
            first: 0,
            rows: img.height,
            channels: img.channels,
        }
    }
}

/// Everything the texels of one n×n resample share: cos θ at the source's row boundaries,
/// its meridians and the column pieces of the four side faces (the source's rows are passed
/// to [`AreaPlan::footprint_mean`], so one plan serves a streamed read's every window).
pub(crate) struct AreaPlan {
    w: usize,
    h: usize,
    n: usize,
    step: f64,
    rot: f64,
    /// cos(π j / H) for j = 0 … H.
    cos_row: Vec<f64>,
    /// Indexed by `Face as usize`; empty for ±Y.
    side: [SideColumns; 6],
    /// (cos, sin) of the azimuth 2π(k/W − 0.5) − rot of column boundary k, k = 0 … W−1.
    meridian: Vec<[f64; 2]>,
}

/// A column piece's three Gauss nodes: the source column, the cosines of each node's run
/// ends and its weight (a node whose ray misses the texel has an empty run and weight 0).
#[derive(Clone, Copy, Debug)]
struct Piece {
    col: usize,
    c_top: [f64; 3],
    c_bot: [f64; 3],
    scale: [f64; 3],
}

/// The run of a node that adds nothing.
const EMPTY_RUN: (f64, f64, f64) = (f64::NEG_INFINITY, f64::INFINITY, 0.0);

/// Per-thread scratch: the polar faces' cut list, a texel's pieces and the row-search starts.
#[derive(Default)]
pub(crate) struct Scratch {
    cuts: Vec<(f64, [f64; 2])>,
    pieces: Vec<Piece>,
    /// The last polar texel's right edge (x1, z0, z1 as bits) and its corners' azimuths.
    right_edge: Option<([u64; 3], f64, f64)>,
    hint: [usize; 2],
}

impl Scratch {
    /// Forgets the row-search starts: for a texel that is not its predecessor's right
    /// neighbour (the searches then start from an arccos, not from a far row; the result does
    /// not depend on where they start).
    pub fn forget_rows(&mut self) {
        self.hint = [usize::MAX; 2];
    }
}

impl AreaPlan {
    /// The plan for n×n faces of a `w`×`h` source turned by `rotate_rad` about +Y.
    pub fn new(w: usize, h: usize, n: usize, rotate_rad: f64) -> Self {
        let step = 2.0 / n as f64;
        let mut side: [SideColumns; 6] = Default::default();
        let mut cuts = Vec::new();
        for face in [Face::Px, Face::Nx, Face::Pz, Face::Nz] {
            let sc = &mut side[face as usize];
            sc.start.reserve(n + 1);
            for i in 0..n {
                sc.start.push(sc.pieces.len());
                let s0 = i as f64 * step - 1.0;
                side_pieces(
                    w,
                    face,
                    s0,
                    s0 + step,
                    rotate_rad,
                    &mut cuts,
                    &mut sc.pieces,
                );
            }
            sc.start.push(sc.pieces.len());
        }
        AreaPlan {
            w,
            h,
            n,
            step,
            rot: rotate_rad,
            cos_row: (0..=h).map(|j| (PI * j as f64 / h as f64).cos()).collect(),
            side,
            meridian: (0..w)
                .map(|k| {
                    let (sn, cs) = (2.0 * PI * (k as f64 / w as f64 - 0.5) - rotate_rad).sin_cos();
                    [cs, sn]
                })
                .collect(),
        }
    }

    /// Row containing polar angle θ with cos θ = c (cos_row[j] ≥ c > cos_row[j+1]), searched
    /// from `hint` (the table is strictly decreasing, so the answer does not depend on where
    /// the search starts; a near hint makes it a step or two), which is updated.
    #[inline(always)]
    fn row_of_cos(&self, c: f64, hint: &mut usize) -> usize {
        let c = c.clamp(-1.0, 1.0);
        // A new face row (no hint) starts from the cheap arccos.
        let mut j = if *hint >= self.h {
            ((crate::approx::acos(c) * self.h as f64 / PI) as usize).min(self.h - 1)
        } else {
            *hint
        };
        while j + 1 < self.h && self.cos_row[j + 1] >= c {
            j += 1;
        }
        while j > 0 && self.cos_row[j] < c {
            j -= 1;
        }
        *hint = j;
        j
    }

    /// Column containing azimuth φ (radians, any range), after the rotation offset.
    #[inline]
    fn column_of_phi(&self, phi: f64) -> usize {
        let u = 0.5 + phi / (2.0 * PI);
        let w = self.w as i64;
        let mut x = (u * self.w as f64).floor() as i64;
        // Within a turn of [0, W) but for large rotations: a compare, not a division.
        if x < 0 {
            x += w;
        } else if x >= w {
            x -= w;
        }
        if !(0..w).contains(&x) {
            x = x.rem_euclid(w);
        }
        x as usize
    }

    /// Adds Σ_nodes Σ_rows L(col, row)·(cos θ_lo − cos θ_hi)·scale over a piece's three
    /// node runs (each from cosine `c_top`, the smaller θ, down to `c_bot`) to `acc`, row by
    /// row (the nodes share the column, so each source pixel is read once and the row
    /// search is done for the piece, not per node); returns the weight added.
    #[inline(always)]
    fn accumulate_piece(
        &self,
        src: &Rows,
        p: &Piece,
        acc: &mut [f64; 3],
        hint: &mut [usize; 2],
    ) -> f64 {
        let top = p.c_top[0].max(p.c_top[1]).max(p.c_top[2]);
        let bot = p.c_bot[0].min(p.c_bot[1]).min(p.c_bot[2]);
        if top <= bot {
            return 0.0;
        }
        let j0 = self.row_of_cos(top, &mut hint[0]);
        let j1 = self.row_of_cos(bot, &mut hint[1]);
        // A row outside the rows given is a bug of the caller's window (texel_rows below
        // bounds what any texel reads), never a reason to read another row.
        assert!(
            j0 >= src.first && j1 < src.first + src.rows,
            "area resample: rows {j0}..={j1} read outside the window {}..{}",
            src.first,
            src.first + src.rows
        );
        let ch = src.channels;
        let stride = self.w * ch;
        let data = &src.data[(j0 - src.first) * stride + p.col * ch..];
        let mut total = 0.0;
        for (k, bounds) in self.cos_row[j0..=j1 + 1].windows(2).enumerate() {
            let mut w = 0.0;
            for g in 0..3 {
                // Plain compares (no NaN here): one instruction each, not f64::min's four.
                let hi = if p.c_top[g] < bounds[0] {
                    p.c_top[g]
                } else {
                    bounds[0]
                };
                let lo = if p.c_bot[g] > bounds[1] {
                    p.c_bot[g]
                } else {
                    bounds[1]
                };
                // Branch-free (a node's run may end above or start below this row).
                let d = hi - lo;
                w += if d > 0.0 { d } else { 0.0 } * p.scale[g];
            }
            let t = &data[k * stride..];
            // Image::rgb's reading of 1, 2, 3 or 4 channels.
            let l = match ch {
                1 => [t[0], t[0], t[0]],
                2 => [t[0], t[1], 0.0],
                _ => [t[0], t[1], t[2]],
            };
            acc[0] += l[0] as f64 * w;
            acc[1] += l[1] as f64 * w;
            acc[2] += l[2] as f64 * w;
            total += w;
        }
        total
    }

    /// Mean radiance over cube texel (`face`, i, j) of the turned source, and the solid angle
    /// the integration covered (the exact solid angle of the texel up to quadrature error;
    /// the tests check it).
    pub fn footprint_mean(
        &self,
        src: &Rows,
        sc: &mut Scratch,
        face: Face,
        i: usize,
        j: usize,
    ) -> (Rgb, f64) {
        let mut acc = [0.0f64; 3];
        let (s0, t0) = (i as f64 * self.step - 1.0, j as f64 * self.step - 1.0);
        let (s1, t1) = (s0 + self.step, t0 + self.step);
        if i == 0 {
            sc.hint = [usize::MAX; 2];
        }
        let total = match face {
            Face::Py | Face::Ny => self.polar_face(src, sc, face, s0, s1, t0, t1, &mut acc),
            _ => self.side_face(src, sc, face, i, t0, t1, &mut acc),
        };
        let mean = if total > 0.0 {
            acc.map(|a| (a / total) as f32)
        } else {
            [0.0; 3]
        };
        (mean, total)
    }

    /// The texel of the adaptive filter (`Filter::Adaptive`): the footprint mean
    /// ([`Self::footprint_mean`]) where the texel spans [`RHO_AREA`] source pixels a side or
    /// more, the bilinear reconstruction at its centre ([`Self::bilinear_at_centre`]) where
    /// it spans [`RHO_BILINEAR`] or less, and a linear blend of the two between.
    ///
    /// Why: the footprint mean reads the source as piecewise constant, which is exact for a
    /// shrunk source but shows each source pixel as a flat block when the cube is finer than
    /// the source (a low-resolution panorama, and every face's corners, whose texels subtend
    /// about 0.44× the angle of the face centre's). A mirror then reflects blocks where the
    /// engines' own routes and skyboxes show the bilinear reading of the same panorama
    /// (measured through the glTF Sample Viewer: 4.2% mean error on the mirror sphere from a
    /// 256×128 source at 256², 1.6% with this filter; `docs/notes/resample-adaptive.md`).
    /// The band sits below one source pixel a texel because a bilinear reading taken about
    /// once a source pixel sums a sun's tent worst (0.26–0.43% of a procedural sky's power
    /// with bands at 0.5–1.5 or 1–2, at most 7e-5 with this one). Even so a bilinear reading keeps a
    /// single-pixel sun's power only to a few percent (2.5% measured), so bakes integrate the
    /// area cube and use this one only as their mirror.
    pub fn texel_value(&self, src: &Rows, sc: &mut Scratch, face: Face, i: usize, j: usize) -> Rgb {
        self.adaptive(src, face, i, j, || {
            self.footprint_mean(src, sc, face, i, j).0
        })
    }

    /// [`Self::texel_value`] of a texel whose footprint mean `area` is already known (a
    /// resample that keeps both cubes): the same bits, without integrating again.
    pub fn texel_value_with_area(
        &self,
        area: Rgb,
        src: &Rows,
        face: Face,
        i: usize,
        j: usize,
    ) -> Rgb {
        self.adaptive(src, face, i, j, || area)
    }

    /// The adaptive blend of texel (`face`, i, j), its footprint mean asked of `area` only
    /// where the blend uses it.
    fn adaptive(
        &self,
        src: &Rows,
        face: Face,
        i: usize,
        j: usize,
        area: impl FnOnce() -> Rgb,
    ) -> Rgb {
        let w_area = self.area_weight(face, i, j);
        if w_area >= 1.0 {
            return area();
        }
        let b = self.bilinear_at_centre(src, face, i, j);
        if w_area <= 0.0 {
            return b.map(|v| v as f32);
        }
        blend(b, area(), w_area)
    }

    /// The footprint mean's weight in [`Self::texel_value`]'s blend.
    fn area_weight(&self, face: Face, i: usize, j: usize) -> f64 {
        let rho = self.footprint_pixels(face, i, j);
        ((rho - RHO_BILINEAR) / (RHO_AREA - RHO_BILINEAR)).clamp(0.0, 1.0)
    }

    /// ρ = sqrt(Ω_texel / Ω_pixel): how many source pixels texel (`face`, i, j) spans a side,
    /// from its solid angle step²/(1 + s² + t²)^{3/2} at the centre and the solid angle
    /// (2π/W)(π/H) sin θ of a source pixel at the centre's latitude (toward the poles the
    /// source's pixels shrink, so the footprint mean takes over there).
    fn footprint_pixels(&self, face: Face, i: usize, j: usize) -> f64 {
        let [x, y, z] = self.centre_direction(face, i, j);
        let q = x * x + y * y + z * z;
        let omega_texel = self.step * self.step / (q * q.sqrt());
        let sin_theta = ((x * x + z * z) / q).sqrt();
        let omega_pixel = (2.0 * PI / self.w as f64) * (PI / self.h as f64) * sin_theta;
        if omega_pixel <= 0.0 {
            return f64::INFINITY;
        }
        (omega_texel / omega_pixel).sqrt()
    }

    /// Unnormalised direction of texel (`face`, i, j)'s centre, in f64 (the face table of
    /// docs/CONVENTIONS.md: each component is ±1, ±s or ±t, so the f32 table read at 0 and at
    /// the unit steps gives it exactly).
    fn centre_direction(&self, face: Face, i: usize, j: usize) -> [f64; 3] {
        let s = (i as f64 + 0.5) * self.step - 1.0;
        let t = (j as f64 + 0.5) * self.step - 1.0;
        let o = face.direction(0.0, 0.0);
        let ds = face.direction(1.0, 0.0) - o;
        let dt = face.direction(0.0, 1.0) - o;
        [
            o.x as f64 + s * ds.x as f64 + t * dt.x as f64,
            o.y as f64 + s * ds.y as f64 + t * dt.y as f64,
            o.z as f64 + s * ds.z as f64 + t * dt.z as f64,
        ]
    }

    /// The source's bilinear reconstruction (wrapping in u, clamping in v, as
    /// `equirect::sample_bilinear`) at texel (`face`, i, j)'s centre, the source turned by
    /// the plan's rotation; reads only rows that [`Self::texel_rows`] names for the texel.
    pub fn bilinear_at_centre(&self, src: &Rows, face: Face, i: usize, j: usize) -> [f64; 3] {
        let [x, y, z] = self.centre_direction(face, i, j);
        let u = 0.5 + (z.atan2(x) + self.rot) / (2.0 * PI);
        let v = (x * x + z * z).sqrt().atan2(y) / PI;
        let (w, h) = (self.w as i64, self.h as i64);
        let fx = u * w as f64 - 0.5;
        let fy = v * h as f64 - 0.5;
        let (x0, y0) = (fx.floor(), fy.floor());
        let (ax, ay) = (fx - x0, fy - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let cols = [x0.rem_euclid(w) as usize, (x0 + 1).rem_euclid(w) as usize];
        let rows = [
            y0.clamp(0, h - 1) as usize,
            (y0 + 1).clamp(0, h - 1) as usize,
        ];
        assert!(
            rows[0] >= src.first && rows[1] < src.first + src.rows,
            "adaptive resample: rows {}..={} read outside the window {}..{}",
            rows[0],
            rows[1],
            src.first,
            src.first + src.rows
        );
        let ch = src.channels;
        let texel = |r: usize, c: usize| -> [f64; 3] {
            let t = &src.data[(r - src.first) * self.w * ch + c * ch..];
            // Image::rgb's reading of 1, 2, 3 or 4 channels.
            match ch {
                1 => [t[0] as f64; 3],
                2 => [t[0] as f64, t[1] as f64, 0.0],
                _ => [t[0] as f64, t[1] as f64, t[2] as f64],
            }
        };
        let (a, b) = (texel(rows[0], cols[0]), texel(rows[0], cols[1]));
        let (c, d) = (texel(rows[1], cols[0]), texel(rows[1], cols[1]));
        std::array::from_fn(|k| {
            let top = a[k] + (b[k] - a[k]) * ax;
            let bot = c[k] + (d[k] - c[k]) * ax;
            top + (bot - top) * ay
        })
    }

    /// Source rows `[a, b]` that [`Self::footprint_mean`] may read for texel (`face`, i, j):
    /// those of the polar-angle extremes of the texel's whole square (edges, not only
    /// corners, and the pole when the square holds it), widened by one row each way for
    /// the rounding of the quadrature's own cosines. A streamed read keeps these rows until
    /// the texel is computed (the plan asserts every read falls inside the rows it is given).
    /// `hint` holds the two row searches' starts (as [`Scratch`]'s: any value gives the same
    /// rows, a near one finds them in a step or two).
    pub fn texel_rows(
        &self,
        face: Face,
        i: usize,
        j: usize,
        hint: &mut [usize; 2],
    ) -> (usize, usize) {
        let (s0, t0) = (i as f64 * self.step - 1.0, j as f64 * self.step - 1.0);
        let (s1, t1) = (s0 + self.step, t0 + self.step);
        let (c_max, c_min) = match face {
            Face::Py | Face::Ny => {
                // cos θ' = 1/sqrt(1 + ρ²) from the pole, ρ the distance in the face plane:
                // nearest at the clamped origin (0 when the square holds the pole), farthest
                // at a corner. Both faces' squares are symmetric in the sign of z.
                let near = |lo: f64, hi: f64| 0.0f64.clamp(lo, hi);
                let far = |lo: f64, hi: f64| lo.abs().max(hi.abs());
                let (nx, nz) = (near(s0, s1), near(t0, t1));
                let (fx, fz) = (far(s0, s1), far(t0, t1));
                let c_near = 1.0 / (1.0 + nx * nx + nz * nz).sqrt();
                let c_far = 1.0 / (1.0 + fx * fx + fz * fz).sqrt();
                if face == Face::Py {
                    (c_near, c_far)
                } else {
                    (-c_far, -c_near)
                }
            }
            _ => {
                // cos θ = −t / sqrt(1 + s² + t²): decreasing in t for any s, so the largest
                // is on the top edge t0 and the smallest on the bottom edge t1; along an edge
                // it is monotonic in s², so at the smallest s² (s = 0 when the texel spans
                // it) or the largest, whichever the sign of t favours.
                let s_near = 0.0f64.clamp(s0, s1);
                let (near, far) = (s_near * s_near, (s0 * s0).max(s1 * s1));
                let c = |s2: f64, t: f64| -t / (1.0 + s2 + t * t).sqrt();
                let hi = c(if t0 < 0.0 { near } else { far }, t0);
                let lo = c(if t1 > 0.0 { near } else { far }, t1);
                (hi, lo)
            }
        };
        let a = self.row_of_cos(c_max, &mut hint[0]);
        let b = self.row_of_cos(c_min, &mut hint[1]);
        (a.saturating_sub(1), (b + 1).min(self.h - 1))
    }

    /// The source's width and height, and the face size.
    pub fn sizes(&self) -> (usize, usize, usize) {
        (self.w, self.h, self.n)
    }

    #[allow(clippy::too_many_arguments)]
    fn side_face(
        &self,
        src: &Rows,
        sc: &mut Scratch,
        face: Face,
        i: usize,
        t0: f64,
        t1: f64,
        acc: &mut [f64; 3],
    ) -> f64 {
        debug_assert!(i < self.n);
        let cols = &self.side[face as usize];
        let (tt0, tt1) = (t0 * t0, t1 * t1);
        // The runs' ends first (independent square roots, which overlap), then the sums.
        sc.pieces.clear();
        for p in &cols.pieces[cols.start[i]..cols.start[i + 1]] {
            // cos θ = −t / sqrt(A + t²): the top edge t0 has the smaller θ.
            sc.pieces.push(Piece {
                col: p.col,
                c_top: p.big_a.map(|a| -t0 / (a + tt0).sqrt()),
                c_bot: p.big_a.map(|a| -t1 / (a + tt1).sqrt()),
                scale: p.scale,
            });
        }
        self.accumulate_pieces(src, sc, acc)
    }

    /// Σ of [`Self::accumulate_piece`] over the scratch's pieces, in their order.
    #[inline(always)]
    fn accumulate_pieces(&self, src: &Rows, sc: &mut Scratch, acc: &mut [f64; 3]) -> f64 {
        let mut total = 0.0;
        for p in &sc.pieces {
            total += self.accumulate_piece(src, p, acc, &mut sc.hint);
        }
        total
    }

    /// A polar-face texel: the square [x0,x1]×[z0,z1] of the face plane seen from the pole,
    /// cut into angular pieces at the meridians and at its corners' directions (where the
    /// ray–square distance has kinks), 3 Gauss nodes per piece.
    #[allow(clippy::too_many_arguments)]
    fn polar_face(
        &self,
        src: &Rows,
        sc: &mut Scratch,
        face: Face,
        s0: f64,
        s1: f64,
        t0: f64,
        t1: f64,
        acc: &mut [f64; 3],
    ) -> f64 {
        let rot = self.rot;
        sc.cuts.clear();
        // Face-plane coordinates (X, Z) = horizontal part of the direction: py (s, t), ny (s, −t).
        let north = face == Face::Py;
        let (x0, x1) = (s0, s1);
        let (z0, z1) = if north { (t0, t1) } else { (-t1, -t0) };
        let contains_pole = x0 <= 0.0 && x1 >= 0.0 && z0 <= 0.0 && z1 >= 0.0;
        let xz = [(x0, z0), (x1, z0), (x0, z1), (x1, z1)];
        // The left corners are the previous texel's right ones when it was the left
        // neighbour (same bits in, same atan2 out): two atan2 per texel instead of four.
        let key = [x0, z0, z1].map(f64::to_bits);
        let (left0, left1) = match sc.right_edge {
            Some((k, a, b)) if k == key => (a, b),
            _ => (z0.atan2(x0), z1.atan2(x0)),
        };
        let corners = [left0, z0.atan2(x1), left1, z1.atan2(x1)];
        sc.right_edge = Some(([x1, z0, z1].map(f64::to_bits), corners[1], corners[3]));
        let cuts = &mut sc.cuts;
        // Corner k's direction without trigonometry (but for a corner at the pole, whose
        // angle atan2 chose by the zeros' signs).
        let unit = |k: usize| {
            let (x, z) = xz[k];
            let r = (x * x + z * z).sqrt();
            if r > 0.0 {
                [x / r, z / r]
            } else {
                let (sn, cs) = corners[k].sin_cos();
                [cs, sn]
            }
        };
        // Angular range of the square seen from the pole (less than π wide when it does not
        // contain the pole), unwrapped around its first corner, with the directions of its ends.
        let (phi_lo, phi_hi, dir_lo, dir_hi) = if contains_pole {
            (-PI, PI, [-1.0, 0.0], [-1.0, 0.0])
        } else {
            let (mut lo, mut hi) = (0.0, 0.0);
            let (mut k_lo, mut k_hi) = (0, 0);
            for (k, &c) in corners.iter().enumerate().skip(1) {
                let mut a = c - corners[0];
                if a > PI {
                    a -= 2.0 * PI;
                } else if a < -PI {
                    a += 2.0 * PI;
                }
                if a < lo {
                    (lo, k_lo) = (a, k);
                }
                if a > hi {
                    (hi, k_hi) = (a, k);
                }
            }
            (corners[0] + lo, corners[0] + hi, unit(k_lo), unit(k_hi))
        };
        // Each cut with the unit direction (cos φ, sin φ) of its azimuth.
        cuts.push((phi_lo, dir_lo));
        // The ray–square distance has kinks at the other corners' directions: cut there too.
        for (k, mut a) in corners.into_iter().enumerate() {
            while a < phi_lo {
                a += 2.0 * PI;
            }
            while a > phi_hi {
                a -= 2.0 * PI;
            }
            if a > phi_lo && a < phi_hi {
                cuts.push((a, unit(k)));
            }
        }
        // Meridians: with the rotation, column boundary k sits at azimuth 2π(k/W − 0.5) − rot.
        let w = self.w as f64;
        let k_lo = ((0.5 + (phi_lo + rot) / (2.0 * PI)) * w).floor() + 1.0;
        let k_hi = (0.5 + (phi_hi + rot) / (2.0 * PI)) * w;
        let mut k = k_lo;
        while k < k_hi {
            let m = self.meridian[(k as i64).rem_euclid(self.w as i64) as usize];
            cuts.push((2.0 * PI * (k / w - 0.5) - rot, m));
            k += 1.0;
        }
        // Between the ends, in order (the meridians come sorted: an insertion sort's pass).
        let inner = cuts.len();
        cuts[1..inner].sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        cuts.push((phi_hi, dir_hi));
        sc.pieces.clear();
        for piece in cuts.windows(2) {
            let ((a, [ca, sa]), (b, _)) = (piece[0], piece[1]);
            if b <= a {
                continue;
            }
            let col = self.column_of_phi(0.5 * (a + b) + rot);
            let half = 0.5 * (b - a);
            let mut p = Piece {
                col,
                c_top: [0.0; 3],
                c_bot: [0.0; 3],
                scale: [0.0; 3],
            };
            for (g, (xg, gw)) in GAUSS.into_iter().enumerate() {
                // The node's direction: the piece start's turned by d = φ − a, by the series
                // below on the narrow pieces every source wider than a few dozen pixels makes.
                let d = half * (1.0 + xg);
                let (sn, cs) = if half <= SMALL_TURN {
                    let (sd, cd) = small_sin_cos(d);
                    (sa * cd + ca * sd, ca * cd - sa * sd)
                } else {
                    (0.5 * (a + b) + half * xg).sin_cos()
                };
                // Ray–square intersection (slab method) in the face plane.
                let (mut r_in, mut r_out) = (0.0f64, f64::INFINITY);
                for (d, lo, hi) in [(cs, x0, x1), (sn, z0, z1)] {
                    if d.abs() < 1e-300 {
                        if lo > 0.0 || hi < 0.0 {
                            r_out = -1.0;
                        }
                        continue;
                    }
                    let inv = 1.0 / d;
                    let (ta, tb) = (lo * inv, hi * inv);
                    let (near, far) = if ta < tb { (ta, tb) } else { (tb, ta) };
                    if near > r_in {
                        r_in = near;
                    }
                    if far < r_out {
                        r_out = far;
                    }
                }
                if r_out <= r_in {
                    (p.c_top[g], p.c_bot[g], p.scale[g]) = EMPTY_RUN;
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
                (p.c_top[g], p.c_bot[g], p.scale[g]) = (c_top, c_bot, gw * half);
            }
            sc.pieces.push(p);
        }
        self.accumulate_pieces(src, sc, acc)
    }
}

/// Largest half-width of a polar piece whose nodes are turned by [`small_sin_cos`]: pieces
/// are at most one source column wide (2π/W), so this covers every source from W = 63 up.
const SMALL_TURN: f64 = 0.05;

/// (sin d, cos d) for |d| ≤ 2·[`SMALL_TURN`] by their Taylor series to d⁹ and d¹⁰: the first
/// terms left out, d¹¹/11! and d¹²/12!, are below 3e-19 there, under half an ulp of the result.
#[inline(always)]
fn small_sin_cos(d: f64) -> (f64, f64) {
    let x = d * d;
    // Horner in d² with the factorials' reciprocals (multiplies, not divisions).
    let s = d * (1.0 + x * (-1.0 / 6.0 + x * (1.0 / 120.0 + x * (-1.0 / 5040.0 + x / 362_880.0))));
    let c = 1.0
        + x * (-0.5
            + x * (1.0 / 24.0 + x * (-1.0 / 720.0 + x * (1.0 / 40320.0 - x / 3_628_800.0))));
    (s, c)
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

/// Appends to `out` the column pieces of the side-face texel column [s0, s1] of a W-wide
/// source turned by `rot`: the source column and, per Gauss node, A = 1 + s² and its weight.
/// Pieces of zero width are left out (their column still counts in the stepping).
fn side_pieces(
    w: usize,
    face: Face,
    s0: f64,
    s1: f64,
    rot: f64,
    cuts: &mut Vec<f64>,
    out: &mut Vec<SidePiece>,
) {
    cuts.clear();
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
    let wf = w as f64;
    let (x0, x1) = ((0.5 + f0 / (2.0 * PI)) * wf, (0.5 + f1 / (2.0 * PI)) * wf);
    cuts.push(s0);
    let (lo, hi) = if x0 < x1 { (x0, x1) } else { (x1, x0) };
    let mut k = lo.floor() + 1.0;
    while k < hi {
        // Azimuth of the boundary, then s where P + sQ points along it.
        let phi_b = 2.0 * PI * (k / wf - 0.5) - rot;
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
    let mut col = (start as i64).rem_euclid(w as i64);
    for (k, piece) in cuts.windows(2).enumerate() {
        if k > 0 {
            col = (col + dir).rem_euclid(w as i64);
        }
        let (a, b) = (piece[0], piece[1]);
        if b <= a {
            continue;
        }
        let half = 0.5 * (b - a);
        let mut sp = SidePiece {
            col: col as usize,
            big_a: [0.0; 3],
            scale: [0.0; 3],
        };
        for (g, (x, gw)) in GAUSS.into_iter().enumerate() {
            let s = 0.5 * (a + b) + half * x;
            let big_a = 1.0 + s * s;
            sp.big_a[g] = big_a;
            sp.scale[g] = gw * half / big_a;
        }
        out.push(sp);
    }
}

#[cfg(test)]
#[allow(dead_code)]
#[path = "area_before.rs"]
mod before;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cube::texel_solid_angle;

    #[test]
    fn row_of_cos_is_exact_at_and_between_boundaries_from_any_start() {
        let img = Image::new(8, 37, 3);
        let plan = AreaPlan::new(img.width, img.height, 4, 0.0);
        for start in [0, 5, 18, 36, 1000] {
            for j in 0..37 {
                let mid = (PI * (j as f64 + 0.5) / 37.0).cos();
                assert_eq!(plan.row_of_cos(mid, &mut start.clone()), j);
                // On a boundary the row below it (cos_row[j] ≥ c).
                let edge = plan.cos_row[j];
                assert_eq!(plan.row_of_cos(edge, &mut start.clone()), j);
            }
            assert_eq!(plan.row_of_cos(1.0, &mut start.clone()), 0);
            assert_eq!(plan.row_of_cos(-1.0, &mut start.clone()), 36);
        }
    }

    #[test]
    fn covered_solid_angle_is_the_exact_texel_solid_angle() {
        // With any source, the weights must add up to the texel's solid angle: this checks
        // the geometry of both face kinds, the pole texel and the rotation.
        let img = Image::new(64, 32, 3);
        for n in [1usize, 3, 8] {
            for rot in [0.0, 0.3] {
                let plan = AreaPlan::new(img.width, img.height, n, rot);
                for face in Face::ALL {
                    for j in 0..n {
                        for i in 0..n {
                            let (_, got) = plan.footprint_mean(
                                &Rows::whole(&img),
                                &mut Scratch::default(),
                                face,
                                i,
                                j,
                            );
                            let want = texel_solid_angle(i, j, n);
                            assert!(
                                ((got - want) / want).abs() < 1e-6,
                                "{face:?} n={n} ({i},{j}) rot={rot}: {got} vs {want}"
                            );
                        }
                    }
                }
            }
        }
    }

    /// A deterministic source with detail at the pixel scale, a bright spot and black areas.
    fn source(w: usize, h: usize, channels: usize) -> Image {
        let mut img = Image::new(w, h, channels);
        let mut x = 0x9e37_79b9_7f4a_7c15u64;
        for (k, v) in img.data.iter_mut().enumerate() {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let r = (x >> 11) as f32 / (1u64 << 53) as f32;
            *v = if k % 97 == 0 {
                1e5 * r
            } else if (k / channels / w) % 11 == 3 {
                0.0
            } else {
                r * 4.0
            };
        }
        img
    }

    #[test]
    fn same_result_as_the_previous_implementation() {
        // Every texel, every face, against the code this plan replaced (area_before.rs), over
        // source and face sizes that make texels span many, one and a fraction of a source
        // pixel, with and without a rotation, for 1 to 4 channels, and sources narrow enough
        // (W < 63) that the polar nodes take sin_cos instead of the series. The sums are the
        // same terms in another order (the three nodes of a piece added row by row) and the
        // polar nodes are turned by a series: the covered solid angle (f64) agrees to float
        // rounding and the means to the last bit or two of their f32.
        let cases: [(usize, usize, usize, f64); 8] = [
            (64, 32, 8, 0.0),
            (64, 32, 7, 0.3),
            (128, 64, 16, -2.1),
            (32, 16, 24, 0.0),
            (200, 100, 13, 1.0),
            (16, 8, 1, 0.0),
            (96, 48, 2, 4.0),
            (512, 256, 40, 0.7),
        ];
        let (mut compared, mut same) = (0usize, 0usize);
        let (mut worst_mean, mut worst_total) = (0.0f64, 0.0f64);
        for (k, &(w, h, n, rot)) in cases.iter().enumerate() {
            let img = source(w, h, 1 + k % 4);
            let old = before::EquirectTables::new(&img);
            let plan = AreaPlan::new(w, h, n, rot);
            let mut sc = Scratch::default();
            let step = 2.0 / n as f64;
            for face in Face::ALL {
                for j in 0..n {
                    for i in 0..n {
                        let (s0, t0) = (i as f64 * step - 1.0, j as f64 * step - 1.0);
                        let want = before::footprint_mean(
                            &old,
                            face,
                            s0,
                            s0 + step,
                            t0,
                            t0 + step,
                            rot,
                            &mut Vec::new(),
                        );
                        let got = plan.footprint_mean(&Rows::whole(&img), &mut sc, face, i, j);
                        let at = format!("{w}x{h} -> {n} rot {rot} {face:?} ({i},{j})");
                        let total = ((got.1 - want.1) / want.1).abs();
                        let mut mean = 0.0f64;
                        for c in 0..3 {
                            let (g, w) = (got.0[c] as f64, want.0[c] as f64);
                            mean = mean.max((g - w).abs() / w.abs().max(1e-30));
                        }
                        assert!(total < 1e-12 && mean < 1e-6, "{at}: {got:?} vs {want:?}");
                        worst_mean = worst_mean.max(mean);
                        worst_total = worst_total.max(total);
                        compared += 1;
                        same += usize::from(got.0 == want.0);
                    }
                }
            }
        }
        eprintln!(
            "area plan vs previous implementation: {compared} texels, {same} with the same f32 \
             means; worst relative difference {worst_mean:.1e} (means), {worst_total:.1e} (solid angle)"
        );
    }
}
