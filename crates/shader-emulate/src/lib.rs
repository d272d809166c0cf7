//! The CPU side of `conformance/render/shader-check.sh`: input grids for the two emitted
//! shaders (the custom lookup of `prefilter --target custom`, the shipped anisotropic VNDF
//! filtered importance sampling of `aniso-eval --emit-shader`), their CPU emulation — the very
//! functions the Rust tests hold the shaders to (`ibl_prefilter::custom::CustomLookup::read`,
//! `ibl_aniso::ship::shade_specular`) — and the GPU-against-CPU comparison.
//!
//! The exchange format ([`Grid`], JSON): `count` cases of `fields` RGBA float vectors each,
//! flat in `data`. The browser page lays case i out at texel (i mod [`ROW`], i div [`ROW`]) of
//! the output, and its field k at row (i div [`ROW`])·fields + k of the input texture.

#![warn(missing_docs)]

use glam::{Vec2, Vec3};
use ibl_aniso::material::{iso_roughness, Material};
use ibl_aniso::scene::Frame;
use ibl_aniso::ship;
use ibl_core::bordered::BorderedMips;
use ibl_core::cube::{face_texel_index, Face};
use ibl_core::sampling::Pcg32;
use ibl_core::{CubeMips, Cubemap, Rgb};
use ibl_prefilter::custom::{CustomChain, CustomLookup};
use ibl_shexp::dfg::Dfg;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The `format` tag of every grid file.
pub const FORMAT: &str = "ibl-shader-check/1";

/// Cases per row of the page's textures.
pub const ROW: usize = 256;

/// Errors of the tool, by cause.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file that is not what it should be (names the file).
    #[error("{path}: {msg}")]
    Invalid {
        /// The file.
        path: String,
        /// What is wrong with it.
        msg: String,
    },
    /// Reading a chain or an environment failed (ibl-core names the file).
    #[error(transparent)]
    Core(#[from] ibl_core::Error),
}

/// A result of this crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;

fn invalid(path: &Path, msg: impl Into<String>) -> Error {
    Error::Invalid {
        path: path.display().to_string(),
        msg: msg.into(),
    }
}

/// Which emitted shader a grid is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Kind {
    /// `iblCustomSpecular(chain, R, roughness)` of lookup.glsl: one field (R.xyz, roughness).
    Custom,
    /// `anisoFisSpecular(...)` of aniso_fis.glsl: six fields (n, α_t), (t, α_b), (b, F0),
    /// (v, 0), (rotation.xy, 0, 0), (isoSpecular.rgb, 0) — the last the isotropic split sum
    /// computed on the CPU ([`IsoSplitSum`]) and fed to both sides.
    Aniso,
    /// `anisoAsSpecular(...)` of aniso_as.glsl: four fields (n, p_h(n)), (t, grid a),
    /// (b, grid b), (v, F0), and the lobe's `hv-lut` table carried in the grid ([`Grid::lut`]).
    As,
}

impl Kind {
    /// RGBA vectors per input case.
    pub fn fields(self) -> usize {
        match self {
            Kind::Custom => 1,
            Kind::Aniso => 6,
            Kind::As => 4,
        }
    }
}

/// Inputs of the shader, or its outputs (one RGBA vector a case, alpha 1).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Role {
    /// What the page uploads.
    Inputs,
    /// What the shader (or its emulation) returns.
    Outputs,
}

/// A grid of cases (the exchange format, JSON).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Grid {
    /// Always [`FORMAT`].
    pub format: String,
    /// Which shader.
    pub kind: Kind,
    /// Inputs or outputs.
    pub role: Role,
    /// RGBA vectors per case.
    pub fields: usize,
    /// Cases.
    pub count: usize,
    /// count · fields · 4 floats.
    pub data: Vec<f32>,
    /// The 2D table the shader reads besides the cube ([`Kind::As`]'s half-vector LUT).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lut: Option<Lut>,
}

/// An RGBA float table, row 0 first (uploaded as an RGBA32F 2D texture, bilinear, clamped).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Lut {
    /// Width in texels.
    pub width: usize,
    /// Height in texels.
    pub height: usize,
    /// width · height · 4 floats.
    pub data: Vec<f32>,
}

impl Grid {
    /// A grid of `data.len() / (4·fields)` cases.
    pub fn new(kind: Kind, role: Role, data: Vec<f32>) -> Self {
        let fields = match role {
            Role::Inputs => kind.fields(),
            Role::Outputs => 1,
        };
        Grid {
            format: FORMAT.to_string(),
            kind,
            role,
            fields,
            count: data.len() / (4 * fields),
            data,
            lut: None,
        }
    }

    /// The 4·fields floats of case `i`.
    pub fn case(&self, i: usize) -> &[f32] {
        let n = 4 * self.fields;
        &self.data[i * n..(i + 1) * n]
    }

    /// Checks the header against the data; `path` names the file in the error.
    pub fn validate(&self, path: &Path) -> Result<()> {
        if self.format != FORMAT {
            return Err(invalid(
                path,
                format!("format {:?}, expected {FORMAT:?}", self.format),
            ));
        }
        let want = match self.role {
            Role::Inputs => self.kind.fields(),
            Role::Outputs => 1,
        };
        if self.fields != want {
            return Err(invalid(
                path,
                format!(
                    "{} fields per case, {:?} {:?} have {want}",
                    self.fields, self.kind, self.role
                ),
            ));
        }
        if self.count == 0 || self.data.len() != self.count * self.fields * 4 {
            return Err(invalid(
                path,
                format!(
                    "{} floats for {} cases of {} fields",
                    self.data.len(),
                    self.count,
                    self.fields
                ),
            ));
        }
        if self.role == Role::Inputs && self.data.iter().any(|v| !v.is_finite()) {
            return Err(invalid(path, "non-finite input value"));
        }
        if self.kind == Kind::As && self.role == Role::Inputs {
            // The tap grid (a, b) of each case: whole numbers, at most the shipped budget.
            let max = ibl_aniso::ship_as::SHIPPED_AS.taps as f32;
            for i in 0..self.count {
                let c = self.case(i);
                let (a, b) = (c[7], c[11]);
                if a.fract() != 0.0 || b.fract() != 0.0 || a < 1.0 || b < 1.0 || a * b > max {
                    return Err(invalid(
                        path,
                        format!("case {i}: tap grid {a} x {b} is not whole numbers with 1 <= a·b <= {max}"),
                    ));
                }
            }
        }
        match (
            &self.lut,
            self.kind == Kind::As && self.role == Role::Inputs,
        ) {
            (None, true) => return Err(invalid(path, "as inputs carry no \"lut\"")),
            (Some(l), _)
                if l.width == 0
                    || l.height == 0
                    || l.data.len() != l.width * l.height * 4
                    || l.data.iter().any(|v| !v.is_finite()) =>
            {
                return Err(invalid(
                    path,
                    format!(
                        "lut: {} floats for {}x{} RGBA, or a non-finite value",
                        l.data.len(),
                        l.width,
                        l.height
                    ),
                ))
            }
            _ => {}
        }
        Ok(())
    }

    /// Reads and validates a grid file.
    pub fn read(path: &Path) -> Result<Grid> {
        let text = std::fs::read_to_string(path).map_err(|e| invalid(path, e.to_string()))?;
        let g: Grid = serde_json::from_str(&text).map_err(|e| invalid(path, e.to_string()))?;
        g.validate(path)?;
        Ok(g)
    }

    /// Writes the grid atomically (a temporary beside it, renamed over).
    pub fn write(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_string(self).map_err(|e| invalid(path, e.to_string()))?;
        let tmp = path.with_extension("json.partial");
        std::fs::write(&tmp, text).map_err(|e| invalid(&tmp, e.to_string()))?;
        std::fs::rename(&tmp, path).map_err(|e| invalid(path, e.to_string()))
    }
}

/// `n` directions on a Fibonacci lattice tilted off the cube's axes, then the 26 directions
/// towards the cube's face centres, edges and corners (where seamless filtering matters).
pub fn directions(n: usize) -> Vec<Vec3> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let (s, c) = (0.61f64.sin(), 0.61f64.cos());
    let mut out: Vec<Vec3> = (0..n)
        .map(|k| {
            let z = 1.0 - (2 * k + 1) as f64 / n as f64;
            let r = (1.0 - z * z).sqrt();
            let phi = golden * k as f64 + 0.3;
            let (x, y) = (r * phi.cos(), r * phi.sin());
            Vec3::new(x as f32, (y * c - z * s) as f32, (y * s + z * c) as f32)
        })
        .collect();
    for x in -1..=1 {
        for y in -1..=1 {
            for z in -1..=1 {
                if (x, y, z) != (0, 0, 0) {
                    out.push(Vec3::new(x as f32, y as f32, z as f32).normalize());
                }
            }
        }
    }
    out
}

/// The custom lookup's inputs: every direction of [`directions`]`(dirs)` at `roughness`
/// values k/(roughness − 1), 0 and 1 included.
pub fn custom_inputs(dirs: usize, roughness: usize) -> Grid {
    let mut data = Vec::new();
    for d in directions(dirs) {
        for k in 0..roughness {
            let r = k as f32 / (roughness.max(2) - 1) as f32;
            data.extend([d.x, d.y, d.z, r]);
        }
    }
    Grid::new(Kind::Custom, Role::Inputs, data)
}

/// Perceptual roughness and η of the anisotropic grid (η = ±1 and r near 0 are the edges).
pub const ANISO_R: [f32; 7] = [0.02, 0.1, 0.25, 0.4, 0.6, 0.8, 1.0];
/// η of the anisotropic grid.
pub const ANISO_ETA: [f32; 5] = [-1.0, -0.5, 0.0, 0.5, 1.0];
/// Polar angles (radians) of the views about each normal.
pub const ANISO_VIEW_POLAR: [f32; 3] = [0.25, 0.8, 1.25];

/// The renderer's isotropic split sum, the `isoSpecular` argument of the shipped snippet:
/// the prefiltered chain read at r_iso = √((α_t+α_b)/2) in the reflected direction through
/// the custom lookup (`CustomLookup::read`, what lookup.glsl does), times F0·A + B from the DFG
/// table at (n·v, r_iso) — the evaluator's `iso` term (`ibl_aniso::methods`, `split`:
/// E0 = L(A+B), E1 = L·B) in radiance form F0·E0 + (1−F0)·E1.
pub struct IsoSplitSum<'a> {
    /// The prefiltered chain and its alpha (the custom lookup's midpoints), bordered.
    pub chain: &'a CustomChain,
    /// Its lookup (constants from its sidecar).
    pub lookup: &'a CustomLookup,
    /// The DFG table (A, B).
    pub dfg: &'a Dfg,
}

impl IsoSplitSum<'_> {
    /// isoSpecular at normal n, view v (towards the eye), lobe (α_t, α_b), F0 (grey).
    pub fn specular(&self, n: Vec3, v: Vec3, at: f32, ab: f32, f0: f32) -> [f32; 3] {
        let nv = n.dot(v);
        if nv <= 0.0 {
            return [0.0; 3];
        }
        let r = iso_roughness(at, ab);
        let l = self.lookup.read(self.chain, 2.0 * nv * n - v, r);
        let (a, b) = self.dfg.ab(nv, r);
        let e = (l.map(|c| c * (a + b)), l.map(|c| c * b));
        ship::specular(&e, [f0; 3])
    }
}

/// The frames of the anisotropic inputs: normals of [`directions`], each tangent turned about
/// its normal by a helper direction (any orthonormal one where the helper is near the normal).
fn input_frames(normals: usize) -> Vec<Frame> {
    let helpers = directions(normals + 7);
    directions(normals)
        .into_iter()
        .take(normals)
        .enumerate()
        .map(|(k, n)| {
            let h = helpers[(k * 5 + 3) % normals.max(1)];
            let h = if h.cross(n).length() < 0.2 {
                n.any_orthonormal_vector()
            } else {
                h
            };
            let t = (h - n * n.dot(h)).normalize();
            Frame {
                t,
                b: n.cross(t),
                n,
            }
        })
        .collect()
}

/// The anisotropic method's inputs: `normals` frames (normal of [`directions`], tangent turned
/// about it) × [`ANISO_VIEW_POLAR`] views × the (r, η) grid (Kulla–Conty α_t, α_b through
/// `ibl_aniso::material::Material::ggx_kc`, the evaluator's conversion), F0 alternating 1 and
/// 0.04, a per-case rotation of the Hammersley set, and `iso`'s isotropic split sum.
pub fn aniso_inputs(normals: usize, iso: &IsoSplitSum) -> Grid {
    let mut data = Vec::new();
    let mut case = 0u64;
    for (k, frame) in input_frames(normals).into_iter().enumerate() {
        let (n, t) = (frame.n, frame.t);
        for (j, theta) in ANISO_VIEW_POLAR.into_iter().enumerate() {
            let phi = 2.4 * k as f32 + 1.7 * j as f32;
            let v = frame.to_world(Vec3::new(
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            ));
            for r in ANISO_R {
                for eta in ANISO_ETA {
                    let (at, ab) = Material::ggx_kc(r, eta).ggx_alphas().expect("GGX");
                    let f0 = if case.is_multiple_of(2) { 1.0 } else { 0.04 };
                    let mut rng = Pcg32::new(case, 23);
                    let rot = [rng.next_f32(), rng.next_f32()];
                    data.extend([n.x, n.y, n.z, at]);
                    data.extend([t.x, t.y, t.z, ab]);
                    data.extend([frame.b.x, frame.b.y, frame.b.z, f0]);
                    data.extend([v.x, v.y, v.z, 0.0]);
                    data.extend([rot[0], rot[1], 0.0, 0.0]);
                    let s = iso.specular(n, v, at, ab, f0);
                    data.extend([s[0], s[1], s[2], 0.0]);
                    case += 1;
                }
            }
        }
    }
    Grid::new(Kind::Aniso, Role::Inputs, data)
}

/// The Ashikhmin–Shirley method's inputs for the lobe of the `hv-lut` table `lut` (its
/// sidecar beside it, `stem.json`, gives n_u, n_v and p_h(n)): `normals` frames × the views of
/// [`ANISO_VIEW_POLAR`] and two more near grazing, F0 alternating 1 and 0.04, the grid
/// [`ibl_aniso::ship_as::grid_shape`] gives for the lobe at the shipped budget.
pub fn as_inputs(normals: usize, lut: &Path) -> Result<Grid> {
    let img = ibl_core::io::read_image(lut, ibl_core::io::ColorSpace::Linear)?;
    if img.channels != 4 {
        return Err(invalid(
            lut,
            format!("{} channels, an hv-lut table has 4", img.channels),
        ));
    }
    let sidecar = lut.with_extension("json");
    let text = std::fs::read_to_string(&sidecar).map_err(|e| invalid(&sidecar, e.to_string()))?;
    let sc: ibl_lut::hv::Sidecar =
        serde_json::from_str(&text).map_err(|e| invalid(&sidecar, e.to_string()))?;
    if sc.size != img.width || sc.size != img.height {
        return Err(invalid(
            &sidecar,
            format!(
                "size {} but the table is {}x{}",
                sc.size, img.width, img.height
            ),
        ));
    }
    let (a, b) = ibl_aniso::ship_as::grid_shape(sc.nu, sc.nv, ibl_aniso::ship_as::SHIPPED_AS.taps);
    let mut data = Vec::new();
    let mut case = 0u64;
    for (k, frame) in input_frames(normals).into_iter().enumerate() {
        let (n, t) = (frame.n, frame.t);
        for (j, theta) in ANISO_VIEW_POLAR.into_iter().chain([1.45, 1.55]).enumerate() {
            let phi = 2.4 * k as f32 + 1.7 * j as f32;
            let v = frame.to_world(Vec3::new(
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            ));
            let f0 = if case.is_multiple_of(2) { 1.0 } else { 0.04 };
            data.extend([n.x, n.y, n.z, sc.p_h_n as f32]);
            data.extend([t.x, t.y, t.z, a as f32]);
            data.extend([frame.b.x, frame.b.y, frame.b.z, b as f32]);
            data.extend([v.x, v.y, v.z, f0]);
            case += 1;
        }
    }
    let mut g = Grid::new(Kind::As, Role::Inputs, data);
    g.lut = Some(Lut {
        width: img.width,
        height: img.height,
        data: img.data,
    });
    Ok(g)
}

/// The shipped Ashikhmin–Shirley method's CPU emulation (`ibl_aniso::ship_as::shade`, the
/// snippet's steps) at every input case, alpha the most special read among its taps.
pub fn emulate_as(inputs: &Grid, pyramid: &BorderedMips) -> Result<Grid> {
    let lut = inputs.lut.as_ref().ok_or_else(|| Error::Invalid {
        path: "inputs".into(),
        msg: "as inputs carry no lut".into(),
    })?;
    let mut img = ibl_core::Image::new(lut.width, lut.height, 4);
    img.data.copy_from_slice(&lut.data);
    let bias = ibl_aniso::ship_as::SHIPPED_AS.lod_bias;
    let sizes = pyramid.sizes();
    let (log2_sa, max_lod) = (
        pyramid.base_log2_texel_solid_angle(),
        pyramid.max_lod() as f32,
    );
    let mut data = Vec::with_capacity(inputs.count * 4);
    for i in 0..inputs.count {
        let c = inputs.case(i);
        let v3 = |k: usize| Vec3::new(c[4 * k], c[4 * k + 1], c[4 * k + 2]);
        let frame = Frame {
            n: v3(0),
            t: v3(1),
            b: v3(2),
        };
        let lobe = ibl_aniso::ship_as::Lobe {
            lut: &img,
            pdf_h_n: c[3],
            grid: (c[7] as usize, c[11] as usize),
        };
        let f0 = c[15];
        let e = ibl_aniso::ship_as::shade(pyramid, &lobe, &frame, v3(3), bias, None);
        let rgb = ship::specular(&e, [f0; 3]);
        let vl = frame.to_local(v3(3)).normalize();
        let mut class = ReadClass::Exact;
        if vl.z > 0.0 {
            ibl_aniso::ship_as::for_each_tap(
                &lobe,
                vl,
                log2_sa,
                max_lod,
                bias,
                None,
                |l, _, lod| {
                    let w = frame.to_world(l);
                    class = class.max(ReadClass::of(w, read_touches_corner(&sizes, w, lod)));
                },
            );
        }
        data.extend([rgb[0], rgb[1], rgb[2], class.alpha()]);
    }
    Ok(Grid::new(Kind::As, Role::Outputs, data))
}

/// The grid with every input moved by a relative `eps` (uniform in ±eps, seeded): for
/// diagnosis, how much the emulation itself moves under perturbations of the size of float
/// rounding (the conditioning a GPU's differently rounded arithmetic meets). Materials (α, F0)
/// are kept.
pub fn jitter(inputs: &Grid, eps: f32, seed: u64) -> Grid {
    let mut g = inputs.clone();
    let keep: &[usize] = match g.kind {
        Kind::Custom => &[3],
        Kind::Aniso => &[3, 7, 11, 15, 18, 19, 23],
        Kind::As => &[3, 7, 11, 15],
    };
    let n = 4 * g.fields;
    let mut rng = Pcg32::new(seed, 99);
    for (k, v) in g.data.iter_mut().enumerate() {
        let u = 2.0 * rng.next_f32() - 1.0;
        if !keep.contains(&(k % n)) {
            *v *= 1.0 + eps * u;
        }
    }
    g
}

/// The alpha channel of a custom chain's container (the lookup's midpoints),
/// refused in a line when the file has none (faces, or a format without alpha).
pub fn chain_alpha(path: &Path) -> Result<CubeMips> {
    ibl_core::envmap::read_cube_chain_alpha(path)?.ok_or_else(|| {
        invalid(
            path,
            "no alpha channel (the custom lookup's correction needs an rgba16f or rgba32f container)",
        )
    })
}

/// The custom lookup of a chain as its `prefilter.json` states it, rebuilt by
/// [`CustomLookup::new`] from α₀ and the chain's shape, and refused when the sidecar's
/// constants are not the ones that rebuild gives (the shader text carries those).
pub fn custom_lookup_from_sidecar(path: &Path, chain: &CubeMips) -> Result<CustomLookup> {
    let text = std::fs::read_to_string(path).map_err(|e| invalid(path, e.to_string()))?;
    let v: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| invalid(path, e.to_string()))?;
    let c = v
        .get("custom_lookup")
        .ok_or_else(|| invalid(path, "no \"custom_lookup\" (not a --target custom bake)"))?;
    let num = |k: &str| {
        c.get(k)
            .and_then(|x| x.as_f64())
            .ok_or_else(|| invalid(path, format!("custom_lookup.{k} missing")))
    };
    let mut lk = CustomLookup::new(
        num("alpha0")? as f32,
        chain.levels.len(),
        chain.levels[0].size,
    );
    // The chain's power factors (fitted to its environment; the shader text carries them).
    let power: Option<Vec<[f32; 2]>> = c
        .get("power")
        .and_then(|p| serde_json::from_value::<Vec<[f32; 2]>>(p.clone()).ok())
        .filter(|p| p.iter().flatten().all(|x| x.is_finite()));
    match power {
        Some(p) if p.len() == lk.power.len() => lk.power = p,
        _ => {
            return Err(invalid(
                path,
                format!(
                    "custom_lookup.power is missing or not {} finite pairs",
                    lk.power.len()
                ),
            ))
        }
    }
    let stated = [num("scale")?, num("inv_alpha0")?, num("max_lod")?].map(|x| x as f32);
    if stated != [lk.scale, lk.inv_alpha0, lk.max_lod]
        || num("levels")? as usize != lk.levels
        || num("size")? as usize != lk.size
    {
        return Err(invalid(
            path,
            format!(
                "custom_lookup {stated:?} is not the lookup of this {}-level {}² chain {:?}",
                lk.levels,
                lk.size,
                [lk.scale, lk.inv_alpha0, lk.max_lod]
            ),
        ));
    }
    Ok(lk)
}

/// Whether a bilinear read of an n×n level at face coordinates (sc, tc) needs a texel beyond
/// two face edges at once, the cube-corner texel. OpenGL leaves it to the implementation
/// (OpenGL 4.2 §3.10.10 / 4.6 §8.13.1, seamless cube map filtering: "The recommended method to
/// generate this texel is to average the values of the three available samples. However,
/// implementations are free to construct this fourth texel in another way"); ibl-core's
/// emulation (`ibl_core::cube`, `ibl_core::bordered`) takes that mean, as SwiftShader does.
pub fn corner_footprint(n: usize, sc: f32, tc: f32) -> bool {
    let n = n as f32;
    let out = |c: f32| {
        let x0 = ((c + 1.0) * 0.5 * n - 0.5).floor();
        x0 < 0.0 || x0 + 1.0 > n - 1.0
    };
    out(sc) && out(tc)
}

/// Whether a trilinear read (`BorderedMips::sample`) of a chain of face sizes `sizes` at `lod`
/// in direction `d` touches a cube-corner texel on either level it blends.
pub fn read_touches_corner(sizes: &[usize], d: Vec3, lod: f32) -> bool {
    let lod = lod.clamp(0.0, (sizes.len() - 1) as f32);
    let l0 = lod.floor() as usize;
    let (_, sc, tc) = Face::from_direction(d);
    corner_footprint(sizes[l0], sc, tc)
        || (lod > l0 as f32 && l0 + 1 < sizes.len() && corner_footprint(sizes[l0 + 1], sc, tc))
}

/// Alpha of an emulated output that reads no texel: the shipped snippet at η = 0, which
/// returns its `isoSpecular` argument untouched (the comparison wants it bit for bit).
pub const ALPHA_PASS_THROUGH: f32 = 2.0;

/// What texels a read uses, as the comparison groups the cases.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum ReadClass {
    /// Only texels of a face or across one edge (defined by the GL specification).
    Exact,
    /// A cube-corner texel (the mean of three, as the GL specification recommends and
    /// SwiftShader does; gated like the rest).
    Corner,
    /// A cube-corner texel read in a direction exactly at a cube corner (|x| = |y| = |z|):
    /// the face choice is a tie, which SwiftShader breaks differently (reported only).
    Tie,
}

impl ReadClass {
    /// The class of a read in direction `d` that touches a cube-corner texel or not.
    pub fn of(d: Vec3, touches_corner: bool) -> ReadClass {
        let a = d.abs();
        match touches_corner {
            false => ReadClass::Exact,
            true if a.x == a.y && a.y == a.z => ReadClass::Tie,
            true => ReadClass::Corner,
        }
    }

    /// The alpha an emulated output carries: 1, 0.5, 0.
    pub fn alpha(self) -> f32 {
        match self {
            ReadClass::Exact => 1.0,
            ReadClass::Corner => 0.5,
            ReadClass::Tie => 0.0,
        }
    }

    /// The class an emulated output's alpha names.
    pub fn from_alpha(a: f32) -> ReadClass {
        if a == 1.0 {
            ReadClass::Exact
        } else if a == 0.0 {
            ReadClass::Tie
        } else {
            ReadClass::Corner
        }
    }
}

/// The custom lookup's CPU emulation ([`CustomLookup::read`]) at every input case; alpha
/// flags the cases whose read touches a cube-corner texel ([`ReadClass::alpha`]).
pub fn emulate_custom(inputs: &Grid, chain: &CustomChain, lk: &CustomLookup) -> Grid {
    let mut data = Vec::with_capacity(inputs.count * 4);
    let sizes = chain.rgb.sizes();
    for i in 0..inputs.count {
        let c = inputs.case(i);
        let d = Vec3::new(c[0], c[1], c[2]);
        let rgb = lk.read(chain, d, c[3]);
        let class = ReadClass::of(d, read_touches_corner(&sizes, d, lk.lod(c[3])));
        data.extend([rgb[0], rgb[1], rgb[2], class.alpha()]);
    }
    Grid::new(Kind::Custom, Role::Outputs, data)
}

/// The pyramid the shipped anisotropic snippet reads on the GPU: `base` and its plain 2×2 box
/// mips down to 1×1, what `generateMipmap` builds (each texel the unweighted mean of four).
/// Not `CubeMips::build` (the evaluator's pyramid, `ibl_aniso::eval`), whose reduction weights
/// the four by their solid angles: on the 4×4…1×1 levels the rough taps read, the two differ
/// by several percent where the environment has contrast (docs/notes/corner.md).
pub fn aniso_pyramid(base: ibl_core::Cubemap) -> BorderedMips {
    let mut levels = vec![base];
    while levels.last().unwrap().size > 1 {
        let prev = levels.last().unwrap();
        let (n, m) = (prev.size, (prev.size / 2).max(1));
        let mut next = Cubemap::new(m);
        for (f, face) in next.faces.iter_mut().enumerate() {
            let src = &prev.faces[f];
            for j in 0..m {
                for i in 0..m {
                    // Odd sizes (never from a KTX2 power of two): the last row/column folded in.
                    let (i1, j1) = (
                        if i == m - 1 { n } else { 2 * i + 2 },
                        if j == m - 1 { n } else { 2 * j + 2 },
                    );
                    let mut acc = [0.0f32; 3];
                    let mut w = 0.0f32;
                    for y in 2 * j..j1 {
                        for x in 2 * i..i1 {
                            let t = src.texel(x, y);
                            (0..3).for_each(|k| acc[k] += t[k]);
                            w += 1.0;
                        }
                    }
                    face.texel_mut(i, j).copy_from_slice(&acc.map(|a| a / w));
                }
            }
        }
        levels.push(next);
    }
    BorderedMips::new(&CubeMips { levels })
}

/// The shipped anisotropic method's CPU emulation (`ibl_aniso::ship::shade_specular`, the
/// snippet's steps, with the case's isoSpecular input) at every input case; alpha
/// [`ALPHA_PASS_THROUGH`] where the blend weight is 0 (η = 0: iso returned, no tap).
pub fn emulate_aniso(inputs: &Grid, pyramid: &BorderedMips) -> Grid {
    let mut data = Vec::with_capacity(inputs.count * 4);
    for i in 0..inputs.count {
        let c = inputs.case(i);
        let v3 = |k: usize| Vec3::new(c[4 * k], c[4 * k + 1], c[4 * k + 2]);
        let frame = Frame {
            n: v3(0),
            t: v3(1),
            b: v3(2),
        };
        let rot = Vec2::new(c[16], c[17]);
        let iso = [c[20], c[21], c[22]];
        let rgb = ship::shade_specular(pyramid, &frame, v3(3), (c[3], c[7]), [c[11]; 3], rot, iso);
        let alpha = if ship::fis_weight(c[3], c[7]) <= 0.0 {
            ALPHA_PASS_THROUGH
        } else {
            aniso_read_class(pyramid, &frame, v3(3), c[3], c[7], rot).alpha()
        };
        data.extend([rgb[0], rgb[1], rgb[2], alpha]);
    }
    Grid::new(Kind::Aniso, Role::Outputs, data)
}

/// The most special read among the shipped method's taps (`ibl_aniso::ship::shade`'s loop, its
/// geometry only: the same pub steps in the same order): a tie, else a cube-corner texel.
fn aniso_read_class(
    pyr: &BorderedMips,
    frame: &Frame,
    v: Vec3,
    at: f32,
    ab: f32,
    rotation: Vec2,
) -> ReadClass {
    let c = ship::SHIPPED;
    let (at, ab) = (at.max(c.alpha_min), ab.max(c.alpha_min));
    let vl = frame.to_local(v).normalize();
    if vl.z <= 0.0 {
        return ReadClass::Exact;
    }
    let g1 = 1.0 / (1.0 + ship::lambda(vl, at, ab));
    let sizes = pyr.sizes();
    let max_lod = pyr.max_lod() as f32;
    (0..c.taps)
        .map(|i| {
            let m = ship::sample_vndf(vl, ship::hammersley(i, rotation), at, ab);
            let l = 2.0 * vl.dot(m) * m - vl;
            if l.z <= 0.0 {
                return ReadClass::Exact;
            }
            let pl = g1 * ship::d_ggx(m, at, ab) / (4.0 * vl.z);
            let lod = if pl > 0.0 {
                (0.5 * (-(c.taps as f32 * pl).log2() - pyr.base_log2_texel_solid_angle())
                    + c.lod_bias)
                    .clamp(0.0, max_lod)
            } else {
                max_lod
            };
            let w = frame.to_world(l);
            ReadClass::of(w, read_touches_corner(&sizes, w, lod))
        })
        .max()
        .unwrap_or(ReadClass::Exact)
}

/// A GPU model of the custom lookup's read, written apart from `ibl_core::bordered` (a
/// cross-check of it): trilinear, seamless across edges (the neighbour face's texel through
/// its direction), and the cube-corner texel the average of the three available ones, as the
/// GL specification recommends. It found the corner rule ibl-core once lacked; the two now
/// agree everywhere (test `gl_model_matches_the_emulation_everywhere`).
pub fn gl_corner_read(chain: &CubeMips, d: Vec3, lod: f32) -> Rgb {
    let lod = lod.clamp(0.0, (chain.levels.len() - 1) as f32);
    let l0 = lod.floor() as usize;
    let a = gl_bilinear(&chain.levels[l0], d);
    if lod <= l0 as f32 || l0 + 1 >= chain.levels.len() {
        return a;
    }
    let b = gl_bilinear(&chain.levels[l0 + 1], d);
    let f = lod - l0 as f32;
    std::array::from_fn(|k| a[k] + (b[k] - a[k]) * f)
}

fn gl_texel(cube: &Cubemap, face: Face, i: isize, j: isize) -> Rgb {
    let n = cube.size as isize;
    let inside = |x: isize| (0..n).contains(&x);
    let clamp = |x: isize| x.clamp(0, n - 1);
    let wrapped = |i: isize, j: isize| {
        let c = |x: isize| 2.0 * (x as f32 + 0.5) / n as f32 - 1.0;
        let (f2, sc, tc) = Face::from_direction(face.direction(c(i), c(j)));
        let (i2, j2) = face_texel_index(sc, tc, cube.size);
        cube.texel(f2, i2, j2)
    };
    match (inside(i), inside(j)) {
        (true, true) => cube.texel(face, i as usize, j as usize),
        (false, false) => {
            let t = [
                cube.texel(face, clamp(i) as usize, clamp(j) as usize),
                wrapped(i, clamp(j)),
                wrapped(clamp(i), j),
            ];
            std::array::from_fn(|k| (t[0][k] + t[1][k] + t[2][k]) / 3.0)
        }
        _ => wrapped(i, j),
    }
}

fn gl_bilinear(cube: &Cubemap, d: Vec3) -> Rgb {
    let (face, sc, tc) = Face::from_direction(d);
    let n = cube.size as f32;
    let (x, y) = ((sc + 1.0) * 0.5 * n - 0.5, (tc + 1.0) * 0.5 * n - 0.5);
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let (i, j) = (x0 as isize, y0 as isize);
    let (a, b) = (gl_texel(cube, face, i, j), gl_texel(cube, face, i + 1, j));
    let (c, e) = (
        gl_texel(cube, face, i, j + 1),
        gl_texel(cube, face, i + 1, j + 1),
    );
    std::array::from_fn(|k| {
        let top = a[k] + (b[k] - a[k]) * fx;
        let bot = c[k] + (e[k] - c[k]) * fx;
        top + (bot - top) * fy
    })
}

/// The custom lookup with each tap read by the GPU model's bilinear (`gl_bilinear`, what
/// [`gl_corner_read`] reads per level; diagnosis), alpha as
/// [`emulate_custom`]'s.
pub fn emulate_custom_gl_corners(
    inputs: &Grid,
    chain: &CubeMips,
    alpha: &CubeMips,
    lk: &CustomLookup,
) -> Grid {
    let sizes: Vec<usize> = chain.levels.iter().map(|l| l.size).collect();
    let mut data = Vec::with_capacity(inputs.count * 4);
    let last = chain.levels.len() - 1;
    for i in 0..inputs.count {
        let c = inputs.case(i);
        let d = Vec3::new(c[0], c[1], c[2]);
        let rgb = lk.read_taps(c[3], |l| {
            let [x, y, z] = gl_bilinear(&chain.levels[l.min(last)], d);
            [x, y, z, gl_bilinear(&alpha.levels[l.min(last)], d)[0]]
        });
        let class = ReadClass::of(d, read_touches_corner(&sizes, d, lk.lod(c[3])));
        data.extend([rgb[0], rgb[1], rgb[2], class.alpha()]);
    }
    Grid::new(Kind::Custom, Role::Outputs, data)
}

/// GPU against CPU: per case the largest relative difference over R, G, B,
/// |gpu − cpu| / max(|cpu|, floor), floor = 10⁻³ × the mean |cpu| (black texels do not divide
/// by zero); a non-finite GPU value counts as infinite.
#[derive(Clone, Debug, Serialize)]
pub struct Stats {
    /// Cases compared.
    pub count: usize,
    /// Mean of the per-case relative difference.
    pub mean: f64,
    /// Its 99th percentile.
    pub p99: f64,
    /// Its maximum.
    pub max: f64,
    /// The case of the maximum (index in the grid).
    pub worst: usize,
}

/// The comparison, split as the emulation's alpha flags the cases ([`ReadClass`]): reads of
/// texels the GL specification defines, reads touching a cube-corner texel (the mean of three,
/// its recommendation), and those at an exact cube-corner direction (a tie of the face choice).
#[derive(Clone, Debug, Serialize)]
pub struct Comparison {
    /// The denominator's floor.
    pub floor: f64,
    /// Cases whose reads touch no cube-corner texel.
    pub exact: Option<Stats>,
    /// Cases whose reads touch one (not at a tie).
    pub corner: Option<Stats>,
    /// Cases the emulation returns an input untouched ([`ALPHA_PASS_THROUGH`]: the aniso
    /// snippet's isoSpecular at η = 0), which the shader must return bit for bit.
    pub pass_through: Option<Stats>,
    /// How many of those the shader returned bit-identical (R, G, B).
    pub pass_through_identical: usize,
    /// Cases whose reads touch one in a direction exactly at a cube corner.
    pub tie: Option<Stats>,
}

fn stats(rel: &[(usize, f64)]) -> Option<Stats> {
    if rel.is_empty() {
        return None;
    }
    let worst = rel.iter().max_by(|a, b| a.1.total_cmp(&b.1)).unwrap();
    let mut sorted: Vec<f64> = rel.iter().map(|r| r.1).collect();
    sorted.sort_by(f64::total_cmp);
    let k = ((sorted.len() as f64 * 0.99).ceil() as usize).clamp(1, sorted.len()) - 1;
    Some(Stats {
        count: rel.len(),
        mean: sorted.iter().sum::<f64>() / sorted.len() as f64,
        p99: sorted[k],
        max: worst.1,
        worst: worst.0,
    })
}

/// Compares the shader's outputs `gpu` with the emulation's `cpu` (same kind, same count).
pub fn compare(cpu: &Grid, gpu: &Grid, gpu_path: &Path) -> Result<Comparison> {
    if cpu.kind != gpu.kind || cpu.count != gpu.count || gpu.role != Role::Outputs {
        return Err(invalid(
            gpu_path,
            format!(
                "{:?} {:?} of {} cases, the emulation has {:?} outputs of {}",
                gpu.kind, gpu.role, gpu.count, cpu.kind, cpu.count
            ),
        ));
    }
    let mut sum = 0.0f64;
    for i in 0..cpu.count {
        sum += cpu.case(i)[..3].iter().map(|v| v.abs() as f64).sum::<f64>();
    }
    let floor = (1e-3 * sum / (3 * cpu.count) as f64).max(f64::MIN_POSITIVE);
    let (mut exact, mut corner, mut tie, mut pass) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut identical = 0;
    for i in 0..cpu.count {
        let (c, g) = (cpu.case(i), gpu.case(i));
        let rel = (0..3)
            .map(|k| {
                if !g[k].is_finite() {
                    f64::INFINITY
                } else {
                    (g[k] as f64 - c[k] as f64).abs() / (c[k].abs() as f64).max(floor)
                }
            })
            .fold(0.0, f64::max);
        if c[3] == ALPHA_PASS_THROUGH {
            identical += (0..3).all(|k| c[k].to_bits() == g[k].to_bits()) as usize;
            pass.push((i, rel));
            continue;
        }
        match ReadClass::from_alpha(c[3]) {
            ReadClass::Exact => exact.push((i, rel)),
            ReadClass::Corner => corner.push((i, rel)),
            ReadClass::Tie => tie.push((i, rel)),
        }
    }
    Ok(Comparison {
        floor,
        exact: stats(&exact),
        corner: stats(&corner),
        pass_through: stats(&pass),
        pass_through_identical: identical,
        tie: stats(&tie),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `f(iso)` with the isotropic split sum over a constant environment (L = 1 everywhere).
    fn with_unit_iso<T>(f: impl FnOnce(&IsoSplitSum) -> T) -> T {
        let mips = CubeMips::build(Cubemap::constant(8, [1.0; 3]), 4);
        let zero = CubeMips::build(Cubemap::constant(8, [0.0; 3]), 4);
        let chain = CustomChain::new(&mips, &zero);
        let lookup = CustomLookup::new(0.01, mips.levels.len(), 8);
        f(&IsoSplitSum {
            chain: &chain,
            lookup: &lookup,
            dfg: Dfg::standard(),
        })
    }

    fn tmp(name: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("shader-emulate-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d.join(name)
    }

    /// Inputs and outputs survive the file bit for bit, as JSON (what the page parses: a
    /// JS number of the shortest f32 form, stored back into a Float32Array).
    #[test]
    fn grids_round_trip_through_their_files() {
        let mut odd = custom_inputs(8, 3);
        odd.data[0] = f32::MIN_POSITIVE;
        odd.data[1] = 1.0 + f32::EPSILON;
        odd.data[2] = -3.4e38;
        odd.data[5] = 1e-45; // subnormal
        for g in [odd, with_unit_iso(|iso| aniso_inputs(2, iso))] {
            let p = tmp(&format!("{:?}.json", g.kind));
            g.write(&p).unwrap();
            let back = Grid::read(&p).unwrap();
            assert_eq!(back.count, g.count);
            assert!(back
                .data
                .iter()
                .zip(&g.data)
                .all(|(a, b)| a.to_bits() == b.to_bits()));
            assert_eq!(back, g);
            // The JS side: each number parsed as f64 and rounded to f32 is the same float.
            let v: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
            for (x, want) in v["data"].as_array().unwrap().iter().zip(&g.data) {
                assert_eq!((x.as_f64().unwrap() as f32).to_bits(), want.to_bits());
            }
        }
        // The page's outputs: JSON.stringify of a Float32Array's values (f64 printing of f32s).
        let js = r#"{"format":"ibl-shader-check/1","kind":"custom","role":"outputs","fields":1,"count":1,"data":[0.10000000149011612,3.4028234663852886e+38,1.401298464324817e-45,1]}"#;
        let p = tmp("gpu.json");
        std::fs::write(&p, js).unwrap();
        let g = Grid::read(&p).unwrap();
        assert_eq!(g.data, vec![0.1f32, f32::MAX, 1e-45, 1.0]);
    }

    #[test]
    fn malformed_grids_are_refused_with_one_line() {
        let good = custom_inputs(4, 2);
        let p = tmp("bad.json");
        let mut cases: Vec<(String, String)> = Vec::new();
        let mut g = good.clone();
        g.data.pop();
        cases.push(("short".into(), serde_json::to_string(&g).unwrap()));
        let mut g = good.clone();
        g.format = "other/2".into();
        cases.push(("format".into(), serde_json::to_string(&g).unwrap()));
        let mut g = good.clone();
        g.fields = 5;
        cases.push(("fields".into(), serde_json::to_string(&g).unwrap()));
        cases.push(("truncated".into(), "{\"format\":".into()));
        let s = serde_json::to_string(&good)
            .unwrap()
            .replacen("\"data\":[", "\"data\":[1e999,", 1);
        cases.push(("inf".into(), s));
        for (what, text) in cases {
            std::fs::write(&p, text).unwrap();
            let e = Grid::read(&p).unwrap_err().to_string();
            assert!(e.contains("bad.json") && !e.contains('\n'), "{what}: {e}");
        }
    }

    /// The comparison is not a rubber stamp: equal outputs give 0, a 2% error anywhere shows as
    /// 2%, a NaN as infinite, a mismatched grid is refused.
    #[test]
    fn compare_sees_a_wrong_output() {
        let cpu = Grid::new(
            Kind::Custom,
            Role::Outputs,
            (0..400)
                .flat_map(|i| [1.0 + i as f32, 0.5, 0.0, 1.0])
                .collect(),
        );
        let p = Path::new("gpu.json");
        let s = compare(&cpu, &cpu, p).unwrap().exact.unwrap();
        assert_eq!((s.mean, s.max), (0.0, 0.0));
        let mut gpu = cpu.clone();
        gpu.data[4 * 17 + 1] *= 1.02;
        let s = compare(&cpu, &gpu, p).unwrap().exact.unwrap();
        assert!((s.max - 0.02).abs() < 1e-6 && s.worst == 17, "{s:?}");
        gpu.data[4 * 3] = f32::NAN;
        assert!(compare(&cpu, &gpu, p)
            .unwrap()
            .exact
            .unwrap()
            .max
            .is_infinite());
        // Cases the emulation flags (alpha 0.5 corner, 0 tie) are reported apart.
        let mut flagged = cpu.clone();
        flagged.data[4 * 3 + 3] = 0.5;
        flagged.data[4 * 17 + 3] = 0.0;
        // A pass-through case (alpha 2) counts as identical only bit for bit.
        let mut through = cpu.clone();
        through.data[4 * 5 + 3] = ALPHA_PASS_THROUGH;
        through.data[4 * 6 + 3] = ALPHA_PASS_THROUGH;
        let mut off = through.clone();
        off.data[4 * 6] = f32::from_bits(off.data[4 * 6].to_bits() + 1);
        let c = compare(&through, &off, p).unwrap();
        assert_eq!(
            (c.pass_through.unwrap().count, c.pass_through_identical),
            (2, 1)
        );
        assert_eq!(c.exact.unwrap().count, 398);
        let c = compare(&flagged, &gpu, p).unwrap();
        assert!(c.corner.unwrap().max.is_infinite() && c.exact.unwrap().max < 1e-6);
        assert!((c.tie.unwrap().max - 0.02).abs() < 1e-6);
        gpu.data.truncate(8);
        gpu.count = 2;
        assert!(compare(&cpu, &gpu, p).is_err());
    }

    /// The emulation reads the inputs it is given: a lookup of a constant chain returns the
    /// constant, and the anisotropic method under a constant sky returns F0 × its albedo-like
    /// E0 (positive, finite), zero below the horizon.
    #[test]
    fn emulations_on_constant_environments() {
        let cube = ibl_core::Cubemap::constant(8, [2.0, 1.0, 0.5]);
        let mips = CubeMips::build(cube.clone(), 4);
        // A zero correction: the constant comes back at every roughness.
        let zero = CubeMips::build(Cubemap::constant(8, [0.0; 3]), 4);
        let chain = CustomChain::new(&mips, &zero);
        let lk = CustomLookup::new(0.01, mips.levels.len(), 8);
        let out = emulate_custom(&custom_inputs(16, 5), &chain, &lk);
        assert!(out
            .data
            .chunks(4)
            .all(|c| (c[0] - 2.0).abs() < 1e-5 && (c[2] - 0.5).abs() < 1e-5));
        // The GPU model agrees with the emulation (and on a constant cube reads the constant:
        // the GL rule, three equal corner samples give that value).
        let gl = emulate_custom_gl_corners(&custom_inputs(16, 5), &mips, &zero, &lk);
        assert!(gl
            .data
            .chunks(4)
            .zip(out.data.chunks(4))
            .all(|(a, b)| (a[0] - b[0]).abs() < 1e-5 && a[3] == b[3]));
        let inp = with_unit_iso(|iso| aniso_inputs(3, iso));
        let out = emulate_aniso(&inp, &aniso_pyramid(cube));
        let mut passed = 0;
        for i in 0..inp.count {
            let c = out.case(i);
            let x = inp.case(i);
            // η = 0 (α_t = α_b) below the roughness ramp: the isoSpecular input back bit for
            // bit, flagged; the iso input itself is the split sum of L = 1: F0·A + B, in (0, 1].
            let below_ramp = iso_roughness(x[3], x[7]) <= ship::SHIPPED.blend_r0;
            if x[3] == x[7] && below_ramp {
                passed += 1;
                assert_eq!(c[3], ALPHA_PASS_THROUGH);
                assert_eq!(&c[..3], &x[20..23]);
            } else {
                assert_ne!(c[3], ALPHA_PASS_THROUGH);
            }
            assert!(x[20] > 0.0 && x[20] <= 1.0 + 1e-6, "{x:?}");
            let (a, b) = Dfg::standard().ab(
                Vec3::new(x[0], x[1], x[2]).dot(Vec3::new(x[12], x[13], x[14])),
                iso_roughness(x[3], x[7]),
            );
            assert!((x[20] - (x[11] * a + b)).abs() < 1e-5, "{x:?}");
            assert!(
                c[..3].iter().all(|v| v.is_finite() && *v > 0.0 && *v < 2.1),
                "{c:?}"
            );
            // Frames are orthonormal and the views above the surface.
            let n = Vec3::new(x[0], x[1], x[2]);
            let t = Vec3::new(x[4], x[5], x[6]);
            let v = Vec3::new(x[12], x[13], x[14]);
            assert!(n.dot(t).abs() < 1e-5 && v.dot(n) > 0.3);
        }
        // Every η = 0 case at r ≤ r₀ (0.02, 0.1, 0.25: 3 of the 7 r), and r = 0.02 at any η
        // (Kulla–Conty's α floor makes α_t = α_b).
        let per_r = inp.count / ANISO_R.len();
        let below = ANISO_R
            .iter()
            .filter(|&&r| r <= ship::SHIPPED.blend_r0)
            .count();
        assert_eq!(below, 3);
        assert_eq!(passed, (below - 1) * per_r / ANISO_ETA.len() + per_r);
    }

    /// The aniso emulation's pyramid is generateMipmap's: every coarse texel the unweighted
    /// mean of the four below it (so a level's plain mean is kept), which the solid-angle
    /// weighted `CubeMips::build` is not.
    #[test]
    fn aniso_pyramid_is_the_plain_box_chain() {
        let cube = Cubemap::from_fn(8, |d| {
            [d.x.max(0.0) * 5.0, 1.0 + d.y, (3.0 * d.z).cos() + 1.5]
        });
        let b = aniso_pyramid(cube.clone());
        assert_eq!(b.sizes(), vec![8, 4, 2, 1]);
        let weighted = BorderedMips::new(&CubeMips::build(cube.clone(), 1));
        let mut moved = 0.0f32;
        for face in Face::ALL {
            for (i, j) in [(0usize, 0usize), (1, 2), (3, 3)] {
                let d = ibl_core::cube::texel_direction(face, i, j, 4);
                let got = b.bilinear(d, 1);
                for k in 0..3 {
                    let want = [(0, 0), (1, 0), (0, 1), (1, 1)]
                        .iter()
                        .map(|&(x, y)| cube.texel(face, 2 * i + x, 2 * j + y)[k])
                        .sum::<f32>()
                        / 4.0;
                    assert!(
                        (got[k] - want).abs() < 1e-5,
                        "{face:?} ({i}, {j}): {got:?} vs {want}"
                    );
                    moved = moved.max((weighted.bilinear(d, 1)[k] - want).abs());
                }
            }
        }
        assert!(moved > 1e-3, "the weighted chain is another chain: {moved}");
    }

    /// The GPU model written apart and ibl-core's sampler read the same values everywhere,
    /// cube-corner texels included (the mean of three on both sides), on a level of every
    /// size down to 1×1.
    #[test]
    fn gl_model_matches_the_emulation_everywhere() {
        let cube = Cubemap::from_fn(8, |d| {
            [
                d.x.max(0.0) * 3.0 + 0.1,
                (d.y * 4.0).sin().abs(),
                0.2 + d.z * d.z,
            ]
        });
        let mips = CubeMips::build(cube, 1);
        let b = BorderedMips::new(&mips);
        let sizes = b.sizes();
        let (mut exact, mut corner) = (0, 0);
        for d in directions(400) {
            for k in 0..9 {
                let lod = k as f32 * 0.45;
                let (e, g) = (b.sample(d, lod), gl_corner_read(&mips, d, lod));
                let diff = (0..3).map(|c| (e[c] - g[c]).abs()).fold(0.0, f32::max);
                match ReadClass::of(d, read_touches_corner(&sizes, d, lod)) {
                    ReadClass::Exact => exact += 1,
                    _ => corner += 1,
                }
                assert!(diff < 1e-5, "{d} lod {lod}: {e:?} vs {g:?}");
            }
        }
        assert!(exact > 1000 && corner > 300, "{exact} {corner}");
        assert_eq!(ReadClass::of(Vec3::splat(-0.5), true), ReadClass::Tie);
        assert_eq!(
            ReadClass::of(Vec3::new(0.5, 0.5, 0.49), true),
            ReadClass::Corner
        );
        for c in [ReadClass::Exact, ReadClass::Corner, ReadClass::Tie] {
            assert_eq!(ReadClass::from_alpha(c.alpha()), c);
        }
        assert!(corner_footprint(4, 0.9, -0.8));
        assert!(!corner_footprint(4, 0.9, 0.0));
        assert!(corner_footprint(1, 0.0, 0.0));
        assert!(!corner_footprint(64, 0.97, 0.97));
    }

    #[test]
    fn as_inputs_read_a_real_hv_lut_and_refuse_a_missing_sidecar() {
        let dir = tempfile::tempdir().unwrap();
        let lut = dir.path().join("hv.exr");
        let params = ibl_lut::hv::Params {
            nu: Some(1000.0),
            nv: Some(20.0),
            ..Default::default()
        };
        let baked = ibl_lut::hv::run(&params, &lut, &ibl_core::progress::NoProgress).unwrap();
        for (path, bytes) in &baked.files {
            std::fs::write(path, bytes).unwrap();
        }
        let g = as_inputs(2, &lut).unwrap();
        assert_eq!((g.kind, g.fields, g.count), (Kind::As, 4, 10));
        let l = g.lut.as_ref().unwrap();
        assert_eq!(l.data.len(), l.width * l.height * 4);
        // The grid of the lobe, p_h(n) from the sidecar.
        let c = g.case(0);
        let want = ibl_aniso::ship_as::grid_shape(1000.0, 20.0, 32);
        assert_eq!((c[7] as usize, c[11] as usize), want);
        let pdf = ibl_brdf_pdf(1000.0, 20.0);
        assert!((c[3] as f64 - pdf).abs() < 1e-3 * pdf, "{} {pdf}", c[3]);
        // JSON round trip keeps the table; a grid without it is refused by name.
        let path = dir.path().join("in.json");
        g.write(&path).unwrap();
        assert_eq!(Grid::read(&path).unwrap(), g);
        let mut big = g.clone();
        big.data[7] = 1e9;
        big.write(&path).unwrap();
        let e = Grid::read(&path).unwrap_err().to_string();
        assert!(e.contains("in.json") && e.contains("tap grid"), "{e}");
        let mut bare = g.clone();
        bare.lut = None;
        bare.write(&path).unwrap();
        let e = Grid::read(&path).unwrap_err().to_string();
        assert!(e.contains("in.json") && e.contains("lut"), "{e}");
        // Under a constant sky every case is F0 × a directional albedo in (0, 1].
        let out = emulate_as(&g, &aniso_pyramid(Cubemap::constant(8, [2.0; 3]))).unwrap();
        for i in 0..out.count {
            let o = out.case(i);
            assert!(
                o[0] > 0.0 && o[0] <= 2.0 && o[0] == o[1] && o[1] == o[2],
                "{o:?}"
            );
        }
        std::fs::remove_file(dir.path().join("hv.json")).unwrap();
        let e = as_inputs(2, &lut).unwrap_err().to_string();
        assert!(e.contains("hv.json"), "{e}");
    }

    fn ibl_brdf_pdf(nu: f64, nv: f64) -> f64 {
        ((nu + 1.0) * (nv + 1.0)).sqrt() / (2.0 * std::f64::consts::PI)
    }
}
