//! Error statistics of a level against a reference ([`ErrorStats`]): shared by the bake, the
//! lookup fit and the runtime report, so it lives below all three (no module cycle).

use ibl_core::cube::Cubemap;
use ibl_core::luminance;
use serde::Serialize;

/// Error of a level against a brute-force reference, on luminance.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ErrorStats {
    /// Mean of |x − ref| / ref.
    pub mean_abs_rel: f64,
    /// sqrt(mean of ((x − ref) / ref)²).
    pub rms_rel: f64,
    /// Largest |x − ref| / ref.
    pub max_abs_rel: f64,
    /// Texels compared.
    pub texels: usize,
}

impl ErrorStats {
    /// Statistics of paired (value, reference) luminances; references below `floor` times the
    /// mean reference are skipped (relative error is meaningless on black).
    pub fn from_pairs(pairs: impl IntoIterator<Item = (f64, f64)>) -> Self {
        let pairs: Vec<(f64, f64)> = pairs.into_iter().collect();
        let mean_ref = pairs.iter().map(|p| p.1).sum::<f64>() / pairs.len().max(1) as f64;
        let floor = 1e-6 * mean_ref.max(1e-30);
        let (mut sa, mut s2, mut mx, mut n) = (0.0f64, 0.0f64, 0.0f64, 0usize);
        for (x, r) in pairs {
            if r <= floor {
                continue;
            }
            let e = (x - r) / r;
            sa += e.abs();
            s2 += e * e;
            mx = mx.max(e.abs());
            n += 1;
        }
        let d = n.max(1) as f64;
        ErrorStats {
            mean_abs_rel: sa / d,
            rms_rel: (s2 / d).sqrt(),
            max_abs_rel: mx,
            texels: n,
        }
    }

    /// Compares two cubes of the same size texel by texel.
    pub fn between(x: &Cubemap, reference: &Cubemap) -> Self {
        assert_eq!(x.size, reference.size, "cubes of different sizes");
        let pairs = (0..6).flat_map(|f| {
            x.faces[f]
                .data
                .chunks_exact(3)
                .zip(reference.faces[f].data.chunks_exact(3))
                .map(|(a, b)| {
                    (
                        luminance([a[0], a[1], a[2]]) as f64,
                        luminance([b[0], b[1], b[2]]) as f64,
                    )
                })
        });
        Self::from_pairs(pairs)
    }
}
