//! Orientations: the pure transform of our cube (docs/CONVENTIONS.md frame) that makes an engine show
//! the environment as intended. Every engine's turn or mirror is a signed permutation of the
//! axes, so it maps texel centres onto texel centres: applying it is an exact face permutation
//! with flips, no resampling.

use glam::Vec3;
use ibl_core::cube::{CubeMips, Cubemap};
use ibl_core::envmap::Layout;
use std::path::{Path, PathBuf};

/// A signed permutation matrix A: the texel of the engine's file in direction t holds our
/// radiance in direction A·t.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Orientation {
    /// Rows of A; each row and column holds one ±1.
    pub ours_from_file: [[i8; 3]; 3],
}

impl Orientation {
    /// Our own frame (glTF viewers).
    pub(crate) const IDENTITY: Orientation = Orientation {
        ours_from_file: [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
    };
    /// z negated: engines that sample cubes as left-handed (Bevy, Unity, Babylon's default
    /// left-handed scene).
    pub(crate) const FLIP_Z: Orientation = Orientation {
        ours_from_file: [[1, 0, 0], [0, 1, 0], [0, 0, -1]],
    };
    /// x negated: three.js samples `CubeTexture`s at (flipEnvMap·x, y, z), flipEnvMap = −1.
    pub(crate) const FLIP_X: Orientation = Orientation {
        ours_from_file: [[-1, 0, 0], [0, 1, 0], [0, 0, 1]],
    };
    /// Our cube turned 90° about +Y: (x, y, z) ↦ (z, y, −x), what cmgen makes of the same
    /// panorama (its equirect longitude atan2(x, z) after its default x mirror).
    pub(crate) const TURN_Y_90: Orientation = Orientation {
        ours_from_file: [[0, 0, 1], [0, 1, 0], [-1, 0, 0]],
    };

    /// Whether A is the identity.
    pub fn is_identity(&self) -> bool {
        *self == Self::IDENTITY
    }

    /// A⁻¹ = Aᵀ (a signed permutation is orthogonal): turns the engine's file back into our
    /// frame, texel for texel.
    pub fn inverse(&self) -> Orientation {
        Orientation {
            ours_from_file: ibl_core::orientation::transpose(&self.ours_from_file),
        }
    }

    /// KTX2 / KTX1 key/value data recording the orientation (every target, ours included, so
    /// a file without it is known to be foreign): [`ibl_core::orientation::METADATA_KEY`].
    pub fn metadata(&self, target: &str) -> Vec<(String, Vec<u8>)> {
        vec![ibl_core::orientation::metadata_entry(
            &self.ours_from_file,
            target,
        )]
    }

    /// Where a layout without key/value data records the orientation: beside a DDS always,
    /// in a folder of EXR faces when it is not our frame (a folder of faces without one is
    /// read in ours, as every tool reads face folders).
    pub fn sidecar_path(&self, dir: &Path, layout: Layout, name: &str) -> Option<PathBuf> {
        match layout {
            Layout::Dds => layout
                .container_path(dir, name)
                .map(|p| ibl_core::orientation::sidecar_path(&p)),
            Layout::Faces if !self.is_identity() => {
                Some(dir.join(ibl_core::orientation::FACES_SIDECAR))
            }
            _ => None,
        }
    }

    /// [`Orientation::sidecar_path`] with its bytes.
    pub fn sidecar(
        &self,
        dir: &Path,
        layout: Layout,
        name: &str,
        target: &str,
    ) -> Option<(PathBuf, Vec<u8>)> {
        self.sidecar_path(dir, layout, name).map(|p| {
            (
                p,
                ibl_core::orientation::sidecar_json(&self.ours_from_file, target),
            )
        })
    }

    /// Our direction A·t for a direction t of the engine's file.
    #[inline]
    pub(crate) fn ours_from_file(&self, t: Vec3) -> Vec3 {
        let r = |row: [i8; 3]| row[0] as f32 * t.x + row[1] as f32 * t.y + row[2] as f32 * t.z;
        Vec3::new(
            r(self.ours_from_file[0]),
            r(self.ours_from_file[1]),
            r(self.ours_from_file[2]),
        )
    }

    #[cfg(test)]
    /// The file direction holding our direction d: Aᵀ·d (A is orthogonal).
    #[inline]
    pub(crate) fn file_from_ours(&self, d: Vec3) -> Vec3 {
        let a = self.ours_from_file;
        let c = |k: usize| a[0][k] as f32 * d.x + a[1][k] as f32 * d.y + a[2][k] as f32 * d.z;
        Vec3::new(c(0), c(1), c(2))
    }

    /// The cube the engine's file holds: texel t of the result is our texel at A·t (exact).
    pub fn apply(&self, cube: &Cubemap) -> Cubemap {
        ibl_core::orientation::transform(cube, &self.ours_from_file)
    }

    /// [`Orientation::apply`] on every level of a chain.
    pub fn apply_mips(&self, mips: &CubeMips) -> CubeMips {
        CubeMips {
            levels: mips.levels.iter().map(|c| self.apply(c)).collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ibl_core::cube::{texel_direction, Face};
    use ibl_core::sampling::Pcg32;

    const ALL: [Orientation; 4] = [
        Orientation::IDENTITY,
        Orientation::FLIP_Z,
        Orientation::FLIP_X,
        Orientation::TURN_Y_90,
    ];

    /// A smooth, direction-distinguishing radiance (no two axes alike).
    fn field(d: Vec3) -> [f32; 3] {
        let d = d.normalize();
        [
            2.0 + d.x + 0.3 * d.y * d.z,
            2.0 + 0.7 * d.y - 0.2 * d.x * d.x,
            2.0 + 0.5 * d.z + 0.4 * d.x * d.y,
        ]
    }

    fn random_dirs(k: usize) -> Vec<Vec3> {
        let mut rng = Pcg32::new(9, 1);
        (0..k)
            .map(|_| {
                Vec3::new(
                    rng.next_f32() - 0.5,
                    rng.next_f32() - 0.5,
                    rng.next_f32() - 0.5,
                )
            })
            .filter(|d| d.length() > 1e-2)
            .collect()
    }

    #[test]
    fn matrices_are_signed_permutations_and_inverses_hold() {
        for o in ALL {
            for d in random_dirs(200) {
                let back = o.file_from_ours(o.ours_from_file(d));
                assert!((back - d).length() < 1e-6);
                assert!((o.ours_from_file(d).length() - d.length()).abs() < 1e-5);
            }
        }
        // TURN_Y_90 is a proper rotation (det +1), the flips are mirrors (det −1).
        let det = |o: Orientation| {
            let a = o.ours_from_file.map(|r| r.map(|v| v as i32));
            a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
                - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
                + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
        };
        assert_eq!(det(Orientation::TURN_Y_90), 1);
        assert_eq!(det(Orientation::FLIP_Z), -1);
        assert_eq!(det(Orientation::FLIP_X), -1);
    }

    #[test]
    fn texels_move_whole_and_the_sampler_reads_our_direction() {
        // Each texel of the file is one whole texel of ours, the one at A·t (a cube whose
        // texels hold their own address shows which); between texels a seamless bilinear read
        // of the file at t equals ours at A·t.
        let n = 6;
        let mut ids = Cubemap::new(n);
        for face in Face::ALL {
            for j in 0..n {
                for i in 0..n {
                    let k = (j * n + i) * 3;
                    ids.faces[face as usize].data[k..k + 3].copy_from_slice(&[
                        face as usize as f32,
                        i as f32,
                        j as f32,
                    ]);
                }
            }
        }
        let ours = Cubemap::from_fn(n, field);
        for o in ALL {
            let moved = o.apply(&ids);
            for face in Face::ALL {
                for j in 0..n {
                    for i in 0..n {
                        let [f, si, sj] = moved.texel(face, i, j);
                        let src = texel_direction(
                            Face::from_index(f as usize),
                            si as usize,
                            sj as usize,
                            n,
                        );
                        let want = o.ours_from_file(texel_direction(face, i, j, n));
                        assert!((src - want).length() < 1e-6, "{o:?}");
                    }
                }
            }
            let file = o.apply(&ours);
            // Away from face edges (where the sampler re-projects border texels, not a
            // mirror-symmetric operation at corners).
            let inner = |t: Vec3| {
                let (_, sc, tc) = Face::from_direction(t);
                sc.abs().max(tc.abs()) < 1.0 - 1.0 / n as f32
            };
            for t in random_dirs(2000).into_iter().filter(|&t| inner(t)) {
                let a = file.sample_bilinear(t);
                let b = ours.sample_bilinear(o.ours_from_file(t));
                for k in 0..3 {
                    assert!((a[k] - b[k]).abs() < 1e-4, "{o:?} {t:?} {a:?} {b:?}");
                }
            }
        }
    }

    #[test]
    fn applying_twice_the_mirrors_is_the_identity_and_four_turns_are_too() {
        let ours = Cubemap::from_fn(4, field);
        for o in [Orientation::FLIP_X, Orientation::FLIP_Z] {
            assert_eq!(o.apply(&o.apply(&ours)).faces, ours.faces);
        }
        let t = Orientation::TURN_Y_90;
        let four = t.apply(&t.apply(&t.apply(&t.apply(&ours))));
        assert_eq!(four.faces, ours.faces);
        assert_ne!(t.apply(&ours).faces, ours.faces);
    }

    #[test]
    fn the_inverse_undoes_every_orientation_texel_for_texel() {
        let ours = Cubemap::from_fn(5, field);
        for o in ALL {
            let inv = o.inverse();
            assert_eq!(inv.apply(&o.apply(&ours)).faces, ours.faces, "{o:?}");
            assert_eq!(o.apply(&inv.apply(&ours)).faces, ours.faces, "{o:?}");
            for d in random_dirs(50) {
                assert!((inv.ours_from_file(d) - o.file_from_ours(d)).length() < 1e-6);
            }
        }
        // A turn's inverse is the turn the other way, not the turn itself.
        assert_ne!(Orientation::TURN_Y_90.inverse(), Orientation::TURN_Y_90);
    }
}
