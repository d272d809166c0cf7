//! The exact lighting of the reference: the GGX-prefiltered radiance Lexact(d, r) of the
//! source environment at any direction and continuous roughness, and the irradiance E(n)/π.
//!
//! - r > 0: the project's exact prefilter kernel K(l) ∝ D_GGX(n·h, α)·max(n·l, 0), h = normalize(n + l),
//!   n = v = d, α = r² (Karis 2013; `ibl_prefilter::kernel`), summed over the source by
//!   `ibl_prefilter`'s cell tree at its `high` preset (measured 0.007% from the brute force
//!   over every texel, bench/prefilter.md) *per pixel*, at the pixel's own reflection
//!   direction: no level, no texel grid, no interpolation between levels.
//! - r = 0: the source itself, read by its own mapping (bilinear in the equirect, or in the
//!   cube for cube inputs), as a mirror reads it.
//! - E(n)/π: `ibl_env::irradiance::convolve_cosine_exact` (Σ L max(n·l, 0) Ω / Σ max(n·l, 0) Ω
//!   over every source texel) on a 64² cube read bilinearly: irradiance varies over tens of
//!   degrees, so the read costs 0.02% on average, 0.3% at worst on city_512 (32²: 0.08% and
//!   1.2%; measured by [`Lighting::estimate`] against the brute force).
//!
//! [`BruteForce`] is the independent check of both: the same kernel written again in f64
//! and summed over the *source's own texels* (equirect pixels with their row solid angles,
//! or cube texels), so it also measures the resampling of the source into the tree's cube.

use glam::{DVec3, Vec3};
use ibl_core::cube::{solid_angle_table, texel_direction, Cubemap, Face};
use ibl_core::envmap::Environment;
use ibl_core::equirect::{self, Filter};
use ibl_core::progress::{NoProgress, Progress};
use ibl_core::Rgb;
use ibl_prefilter::runtime::Reference;
use ibl_prefilter::tree::{CellTree, TreeBuffers, TreeParams};
use ibl_prefilter::Quality;

/// Face size of the irradiance cube E/π (read bilinearly) of the reference.
pub const IRRADIANCE_SIZE: usize = 64;
/// Largest face of the cube the tree sums (its memory grows 4× per doubling: about 200 MB at
/// 512², as in the bake).
pub const MAX_TREE_SIZE: usize = 512;

/// The lighting of one environment, ready to be evaluated at any direction.
pub struct Lighting {
    source: Environment,
    cube: Cubemap,
    tree: CellTree,
    params: TreeParams,
    irradiance: Cubemap,
}

impl Lighting {
    /// Prepares the lighting of `env`: its cube for the tree (an equirect at twice its natural
    /// face size, at most [`MAX_TREE_SIZE`], the area filter keeping the power; a cube as it
    /// is), the tree, and E/π.
    pub fn new(env: &Environment, progress: &dyn Progress) -> Lighting {
        Lighting::with_irradiance_size(env, IRRADIANCE_SIZE, progress)
    }

    /// [`Lighting::new`] with an E/π cube of `irradiance_size`² texels a face (previews use a
    /// smaller one: its cost grows with the square).
    pub fn with_irradiance_size(
        env: &Environment,
        irradiance_size: usize,
        progress: &dyn Progress,
    ) -> Lighting {
        // A cube input is summed as it is (resampling it finer adds nothing); an equirect at
        // twice its natural face size, so the resampling costs far less than the kernel's width.
        let size = match env {
            Environment::Cube(c) => c.size,
            Environment::Equirect(_) => (2 * env.natural_face_size()).clamp(8, MAX_TREE_SIZE),
        };
        let cube = env.to_cube(size, Filter::Area, 0.0, progress);
        let tree = CellTree::new(&cube);
        let irradiance = ibl_env::irradiance::convolve_cosine_exact(
            env,
            irradiance_size.max(1),
            0,
            0.0,
            progress,
        );
        Lighting {
            source: env.clone(),
            cube,
            tree,
            params: Quality::High.tree_params(),
            irradiance,
        }
    }

    /// Face size of the cube the tree sums.
    pub fn tree_size(&self) -> usize {
        self.cube.size
    }

    /// The source environment.
    pub fn source(&self) -> &Environment {
        &self.source
    }

    /// Lexact(d, r): the GGX-prefiltered radiance at roughness `r` in direction `d` (unit).
    /// `buffers` is per-thread scratch.
    pub fn specular(&self, d: DVec3, r: f64, buffers: &mut TreeBuffers) -> Rgb {
        let d = d.as_vec3();
        if r <= 0.0 {
            return mirror(&self.source, d);
        }
        let reference = Reference::Tree {
            tree: &self.tree,
            source: &self.cube,
            params: self.params,
        };
        reference.radiance(d, r as f32, buffers)
    }

    /// E(n)/π: the radiance a white Lambertian surface with normal `n` reflects.
    pub fn irradiance(&self, n: DVec3) -> Rgb {
        self.irradiance.sample_bilinear(n.as_vec3())
    }
}

/// The source read as a mirror reads it: bilinear in its own mapping.
pub fn mirror(env: &Environment, d: Vec3) -> Rgb {
    match env {
        Environment::Equirect(img) => equirect::sample_bilinear(img, d),
        Environment::Cube(c) => c.sample_bilinear(d),
    }
}

/// The kernel of the prefiltered radiance, written again in f64 for the brute force:
/// D_GGX(n·h, α)·max(n·l, 0) without its constant α²/π (which cancels in the normalisation),
/// as a function of s² = sin²θ_h = |n − l|²/4 (n = v, unit n and l): the GGX denominator
/// (n·h)²(α² − 1) + 1 = α² + (1 − α²)s² (Walter et al. 2007 eq. 33) and n·l = 1 − 2s².
/// At α = 1 it is max(n·l, 0): the cosine, so the same sum gives E(n)/π.
pub fn kernel_weight(n: DVec3, l: DVec3, alpha: f64) -> f64 {
    let s2 = 0.25 * (n - l).length_squared();
    let a2 = alpha * alpha;
    let t = a2 + (1.0 - a2) * s2;
    (1.0 - 2.0 * s2).max(0.0) / (t * t)
}

/// Every texel of the source with its direction and solid angle: the brute-force sum.
pub struct BruteForce {
    texels: Vec<(DVec3, [f64; 3], f64)>,
}

impl BruteForce {
    /// The texels of `env` as stored (no resampling).
    pub fn new(env: &Environment) -> BruteForce {
        let mut texels = Vec::new();
        match env {
            Environment::Equirect(img) => {
                for j in 0..img.height {
                    let om = equirect::row_solid_angle(j, img.width, img.height);
                    for i in 0..img.width {
                        let d = equirect::pixel_direction(i, j, img.width, img.height);
                        let c = img.rgb(i, j);
                        texels.push((d.as_dvec3().normalize(), c.map(|v| v as f64), om));
                    }
                }
            }
            Environment::Cube(cube) => {
                let sa = solid_angle_table(cube.size);
                for face in Face::ALL {
                    for j in 0..cube.size {
                        for i in 0..cube.size {
                            let d = texel_direction(face, i, j, cube.size).as_dvec3();
                            let c = cube.texel(face, i, j);
                            texels.push((
                                d.normalize(),
                                c.map(|v| v as f64),
                                sa[j * cube.size + i] as f64,
                            ));
                        }
                    }
                }
            }
        }
        BruteForce { texels }
    }

    /// Σ K L Ω / Σ K Ω over every texel, at roughness `r` > 0 in direction `d` (r = 1 is E/π).
    pub fn radiance(&self, d: DVec3, r: f64) -> [f64; 3] {
        let alpha = r * r;
        let (mut num, mut den) = ([0.0f64; 3], 0.0f64);
        for (l, c, om) in &self.texels {
            let w = kernel_weight(d, *l, alpha) * om;
            if w > 0.0 {
                for k in 0..3 {
                    num[k] += w * c[k];
                }
                den += w;
            }
        }
        if den > 0.0 {
            num.map(|v| v / den)
        } else {
            [0.0; 3]
        }
    }
}

/// The reference's own error at probe pixels, per sphere (what [`Lighting::estimate`] reports).
#[derive(Clone, Debug, serde::Serialize)]
pub struct Estimate {
    /// Sphere index (0..12).
    pub sphere: usize,
    /// Its label.
    pub label: String,
    /// Probe pixels measured.
    pub probes: usize,
    /// Mean |Lexact − brute| / brute of luminance over the probes (0 for the mirror: the
    /// source itself).
    pub specular_mean_rel: f64,
    /// Largest of the same.
    pub specular_max_rel: f64,
    /// Mean |E/π (cube, bilinear) − brute| / brute of luminance (dielectric row only).
    pub irradiance_mean_rel: Option<f64>,
    /// Largest of the same.
    pub irradiance_max_rel: Option<f64>,
}

impl Lighting {
    /// The reference's error against the brute force over the source's own texels, at
    /// `per_sphere` probe pixels of every sphere's mask (a fixed spread, the same every run).
    pub fn estimate(&self, brute: &BruteForce, per_sphere: usize) -> Vec<Estimate> {
        use rayon::prelude::*;
        crate::scene::Sphere::all()
            .par_iter()
            .map(|s| {
                let probes = probe_hits(s, per_sphere);
                let mut buf = TreeBuffers::default();
                let (mut ss, mut sm, mut is, mut im) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
                for h in &probes {
                    if s.roughness > 0.0 {
                        let got = lum(self
                            .specular(h.reflected, s.roughness, &mut buf)
                            .map(|v| v as f64));
                        let want = lum(brute.radiance(h.reflected, s.roughness));
                        let e = rel(got, want);
                        ss += e;
                        sm = sm.max(e);
                    }
                    if !s.metallic {
                        let got = lum(self.irradiance(h.normal).map(|v| v as f64));
                        let want = lum(brute.radiance(h.normal, 1.0));
                        let e = rel(got, want);
                        is += e;
                        im = im.max(e);
                    }
                }
                let k = probes.len().max(1) as f64;
                Estimate {
                    sphere: s.index,
                    label: s.label(),
                    probes: probes.len(),
                    specular_mean_rel: ss / k,
                    specular_max_rel: sm,
                    irradiance_mean_rel: (!s.metallic).then_some(is / k),
                    irradiance_max_rel: (!s.metallic).then_some(im),
                }
            })
            .collect()
    }
}

/// Rec. 709 luminance in f64.
pub(crate) fn lum(c: [f64; 3]) -> f64 {
    0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
}

fn rel(got: f64, want: f64) -> f64 {
    (got - want).abs() / want.max(1e-12)
}

/// About `n` masked pixels of sphere `s`, spread on a golden-angle spiral over its disc.
pub(crate) fn probe_hits(s: &crate::scene::Sphere, n: usize) -> Vec<crate::scene::Hit> {
    let inner =
        crate::scene::RADIUS - crate::scene::RIM_MARGIN_PIXELS / crate::scene::PIXELS_PER_UNIT;
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .filter_map(|k| {
            let rho = inner * ((k as f64 + 0.5) / n as f64).sqrt();
            let phi = golden * k as f64;
            let (x, y) = (s.cx + rho * phi.cos(), s.cy + rho * phi.sin());
            // Snap to the pixel centre the point falls in: probes are real pixels.
            let (px, py) = crate::scene::world_to_pixel(x, y);
            crate::scene::hit(px.round() as usize, py.round() as usize).filter(|h| h.masked)
        })
        .collect()
}

/// A lighting from a constant environment, for tests and the furnace.
pub fn constant(c: Rgb) -> Lighting {
    Lighting::new(&Environment::Cube(Cubemap::constant(8, c)), &NoProgress)
}
