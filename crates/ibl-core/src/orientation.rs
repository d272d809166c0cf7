//! Orientation metadata of a cube written in an engine's frame: the signed permutation A with
//! "texel t of the file holds our radiance in direction A·t" (docs/CONVENTIONS.md frame), kept
//! with the file so a reader can undo it: KTX2 / KTX1 key/value data under [`METADATA_KEY`];
//! DDS (no key/value data) and EXR faces in a sidecar JSON ([`sidecar_path`]).
//!
//! Issue 22: a cube written for Bevy (z negated) or Filament (cmgen's 90° turn) was read back as
//! if in our frame: the SH of Bevy's had L10 with its sign flipped, Filament's L10 and L11
//! swapped. [`crate::envmap::load_environment`] now undoes a recorded orientation and warns
//! when a container carries none.

use crate::cube::{face_texel_index, texel_direction, Cubemap, Face};
use glam::Vec3;
use std::path::{Path, PathBuf};

/// KTX2 / KTX1 key/value key holding the orientation (not `KTX…`/`ktx…`: those keys are the
/// spec's own).
pub const METADATA_KEY: &str = "ibl.orientation";

/// Sidecar of a folder of EXR faces.
pub const FACES_SIDECAR: &str = "orientation.json";

/// Rows of A (ours from file), each row and column holding one ±1.
pub type Matrix = [[i8; 3]; 3];

/// Our own frame.
pub const IDENTITY: Matrix = [[1, 0, 0], [0, 1, 0], [0, 0, 1]];

/// The sidecar recording the orientation of the cube at `path`: `dir/orientation.json` for a
/// folder of faces, `<stem>.orientation.json` beside a container.
pub fn sidecar_path(path: &Path) -> PathBuf {
    if path.is_dir() || path.extension().is_none() {
        return path.join(FACES_SIDECAR);
    }
    let stem = path.file_stem().unwrap_or_default().to_string_lossy();
    path.with_file_name(format!("{stem}.orientation.json"))
}

/// A as text: our x, y, z in terms of the file's axes, e.g. `+x +y -z` (z negated) or
/// `+z +y -x` (a turn about +Y).
pub fn format(m: &Matrix) -> String {
    m.iter()
        .map(|row| {
            let k = row.iter().position(|v| *v != 0).unwrap_or(0);
            let sign = if row[k] < 0 { '-' } else { '+' };
            format!("{sign}{}", ['x', 'y', 'z'][k])
        })
        .collect::<Vec<_>>()
        .join(" ")
}

/// Parses [`format`]'s text; `None` unless it is a signed permutation.
pub fn parse(text: &str) -> Option<Matrix> {
    let parts: Vec<&str> = text.split_whitespace().collect();
    if parts.len() != 3 {
        return None;
    }
    let mut m = [[0i8; 3]; 3];
    let mut used = [false; 3];
    for (row, p) in parts.iter().enumerate() {
        let mut c = p.chars();
        let sign = match c.next()? {
            '+' => 1,
            '-' => -1,
            _ => return None,
        };
        let k = match (c.next()?, c.next()) {
            ('x', None) => 0,
            ('y', None) => 1,
            ('z', None) => 2,
            _ => return None,
        };
        if used[k] {
            return None;
        }
        used[k] = true;
        m[row][k] = sign;
    }
    Some(m)
}

/// The key/value entry a KTX1/KTX2 writer stores (NUL-terminated UTF-8, as the KTX specs
/// recommend for text values): `ours_from_file=<format> target=<name>`.
pub fn metadata_entry(m: &Matrix, target: &str) -> (String, Vec<u8>) {
    let mut v = format!("ours_from_file={} target={target}", format(m)).into_bytes();
    v.push(0);
    (METADATA_KEY.to_string(), v)
}

/// The orientation recorded in key/value data, if any (`Some(Err)` when it is unreadable).
pub fn from_metadata(kv: &[(String, Vec<u8>)]) -> Option<Result<Matrix, String>> {
    let (_, v) = kv.iter().find(|(k, _)| k == METADATA_KEY)?;
    let text = String::from_utf8_lossy(v);
    let text = text.trim_end_matches('\0');
    Some(
        text.strip_prefix("ours_from_file=")
            .and_then(|rest| parse(rest.split(" target=").next().unwrap_or("")))
            .ok_or_else(|| format!("unreadable {METADATA_KEY} metadata '{text}'")),
    )
}

/// The sidecar JSON's bytes.
pub fn sidecar_json(m: &Matrix, target: &str) -> Vec<u8> {
    let mut b = serde_json::to_vec_pretty(&serde_json::json!({
        "ours_from_file": format(m),
        "target": target,
        "meaning": "texel t of the cube holds the docs/CONVENTIONS.md radiance in direction A t; rows of A give our x, y, z in the file's axes",
    }))
    .expect("JSON of strings");
    b.push(b'\n');
    b
}

/// The orientation a sidecar records (`Err` when it is unreadable).
pub fn from_sidecar(bytes: &[u8]) -> Result<Matrix, String> {
    let v: serde_json::Value =
        serde_json::from_slice(bytes).map_err(|e| format!("orientation sidecar: {e}"))?;
    v["ours_from_file"]
        .as_str()
        .and_then(parse)
        .ok_or_else(|| "orientation sidecar: no readable 'ours_from_file'".to_string())
}

/// Aᵀ (A is orthogonal: its inverse).
pub fn transpose(m: &Matrix) -> Matrix {
    let mut t = [[0i8; 3]; 3];
    for (i, row) in m.iter().enumerate() {
        for (j, v) in row.iter().enumerate() {
            t[j][i] = *v;
        }
    }
    t
}

/// M·t for a direction t.
fn mul(m: &Matrix, t: Vec3) -> Vec3 {
    let r = |row: [i8; 3]| row[0] as f32 * t.x + row[1] as f32 * t.y + row[2] as f32 * t.z;
    Vec3::new(r(m[0]), r(m[1]), r(m[2]))
}

/// The cube whose texel t is `cube`'s texel at M·t: exact (a signed permutation maps texel
/// centres onto texel centres). Writing in an engine's frame is `transform(ours, A)`; reading
/// such a file back is `transform(file, Aᵀ)`.
pub fn transform(cube: &Cubemap, m: &Matrix) -> Cubemap {
    if *m == IDENTITY {
        return cube.clone();
    }
    let n = cube.size;
    let mut out = Cubemap::new(n);
    for face in Face::ALL {
        for j in 0..n {
            for i in 0..n {
                let (f, sc, tc) = Face::from_direction(mul(m, texel_direction(face, i, j, n)));
                let (si, sj) = face_texel_index(sc, tc, n);
                let c = cube.texel(f, si, sj);
                let k = (j * n + i) * 3;
                out.faces[face as usize].data[k..k + 3].copy_from_slice(&c);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_round_trips_and_rejects_what_is_not_a_signed_permutation() {
        for m in [
            IDENTITY,
            [[1, 0, 0], [0, 1, 0], [0, 0, -1]],
            [[-1, 0, 0], [0, 1, 0], [0, 0, 1]],
            [[0, 0, 1], [0, 1, 0], [-1, 0, 0]],
        ] {
            assert_eq!(parse(&format(&m)), Some(m));
            let kv = [metadata_entry(&m, "t")];
            assert_eq!(from_metadata(&kv), Some(Ok(m)));
            assert_eq!(from_sidecar(&sidecar_json(&m, "t")), Ok(m));
        }
        assert_eq!(format(&[[0, 0, 1], [0, 1, 0], [-1, 0, 0]]), "+z +y -x");
        for bad in ["+x +x +z", "x y z", "+x +y", "+x +y +w", "+xy +y +z"] {
            assert_eq!(parse(bad), None, "{bad}");
        }
        assert!(from_metadata(&[(METADATA_KEY.into(), b"junk".to_vec())])
            .unwrap()
            .is_err());
        assert!(from_metadata(&[]).is_none());
    }

    #[test]
    fn transform_by_the_transpose_undoes_it() {
        let c = Cubemap::from_fn(4, |d| {
            let d = d.normalize();
            [1.0 + d.x, 2.0 + d.y * d.z, 3.0 + 0.5 * d.z]
        });
        let turn = [[0, 0, 1], [0, 1, 0], [-1, 0, 0]];
        let file = transform(&c, &turn);
        assert_ne!(file.faces, c.faces);
        assert_eq!(transform(&file, &transpose(&turn)).faces, c.faces);
    }

    #[test]
    fn sidecars_sit_beside_their_cube() {
        assert_eq!(
            sidecar_path(Path::new("/o/specular.dds")),
            Path::new("/o/specular.orientation.json")
        );
        assert_eq!(
            sidecar_path(Path::new("/o/cube")),
            Path::new("/o/cube/orientation.json")
        );
    }
}
