//! Engine targets: one table row per engine saying what it loads as-is — container and pixel
//! format, orientation, the level ↔ roughness mapping of its runtime lookup, default chain
//! level count and base size, the diffuse / SH form, the file names its loaders and examples
//! use, and a short how-to-load note. Every convention cites the engine source it was read in.
//!
//! [`lod`] holds the lookups' mappings, [`orient`] the exact cube re-orientations, [`sh`] the
//! engines' SH forms, [`babylon`] the `.env` container.

#![warn(missing_docs)]
// Index loops read closer to the equations in the small numeric kernels.
#![allow(clippy::needless_range_loop)]

pub mod babylon;
pub mod lod;
pub mod note;
pub mod orient;
pub mod sh;
pub mod snippet;

pub use lod::LodMapping;
pub use orient::Orientation;

use ibl_core::envmap::Layout;
use ibl_core::io::format::PixelFormat;

/// The engine a bake is made for (`--target`, RON key `target`).
#[derive(
    Clone,
    Copy,
    Debug,
    PartialEq,
    Eq,
    Hash,
    Default,
    serde::Serialize,
    serde::Deserialize,
    clap::ValueEnum,
)]
#[serde(rename_all = "kebab-case")]
pub enum Target {
    /// glTF-Sample-Viewer / glTF-IBL-Sampler: our own conventions (today's behaviour).
    #[default]
    Gltf,
    /// Bevy (`EnvironmentMapLight`): KTX2 RGB9E5 + zstd, z negated.
    Bevy,
    /// Filament (`IndirectLight`): KTX1 R11F_G11F_B10F, cmgen's roughness and orientation, SH.
    Filament,
    /// three.js: a cube for PMREMGenerator and a `LightProbe` JSON.
    Three,
    /// Babylon.js: `.env` (RGBD PNG mips + JSON manifest with the SH).
    Babylon,
    /// Unity: DDS cube with Unity's mip mapping, SphericalHarmonicsL2.
    Unity,
    /// Our own lookup for renderers written by the user: KTX2 RGBA16F chain whose level
    /// spacing and lookup (lod = s·log2(1 + r²/α₀), two taps and a polynomial through
    /// midpoints kept in the chain's alpha channel) are designed together, the lookup emitted
    /// as GLSL / HLSL / WGSL beside it (docs/CUSTOM_LOOKUP.md).
    Custom,
}

#[cfg(test)]
/// Every target, in help order.
pub(crate) const ALL_TARGETS: [Target; 7] = [
    Target::Gltf,
    Target::Bevy,
    Target::Filament,
    Target::Three,
    Target::Babylon,
    Target::Unity,
    Target::Custom,
];

/// The diffuse term an engine takes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum DiffuseForm {
    /// A cube storing E/π (our irradiance cube), sampled by the normal.
    IrradianceCube,
    /// Nine pre-scaled RGB polynomial coefficients (cmgen's `sh.txt` and KTX1 `sh` metadata):
    /// [`sh::prescaled_polynomial`], [`sh::filament_sh_txt`], [`sh::filament_ktx_sh_metadata`].
    FilamentSh,
    /// 27 radiance coefficients in our basis in a `LightProbe.toJSON` document:
    /// [`sh::three_light_probe_json`].
    ThreeLightProbe,
    /// The `.env` manifest's irradiance harmonics / polynomial.
    BabylonManifest,
    /// Unity's SphericalHarmonicsL2 (pre-multiplied, left-handed): [`sh::unity_sh_l2`].
    UnityShL2,
}

/// File names (stems for cubes, whose extension follows the layout) that the engine's loaders
/// and examples use.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct FileNames {
    /// The specular chain (stem).
    pub specular: &'static str,
    /// The irradiance cube (stem), if the engine takes one.
    pub irradiance: Option<&'static str>,
    /// The SH file, if the engine takes one in a file of its own.
    pub sh: Option<&'static str>,
    /// The environment cube (`equirect-to-cube`, stem).
    pub cube: &'static str,
}

/// Name of the how-to-load note written beside a target's outputs.
pub const NOTE_NAME: &str = "LOAD.txt";

/// What one engine loads as-is.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct TargetSpec {
    /// The target described.
    pub target: Target,
    /// Engine (and the part of it that reads the assets).
    pub engine: &'static str,
    /// Container of the cubes and chains.
    pub layout: Layout,
    /// Pixel format of the cubes and chains.
    pub format: PixelFormat,
    /// KTX2 zstd supercompression level, if the engine's shipped assets use it.
    pub zstd: Option<i32>,
    /// Transform of our cube the engine's file holds.
    pub orientation: Orientation,
    /// The engine's runtime level ↔ roughness mapping.
    pub lod: LodMapping,
    /// Default level count of the specular chain, chosen on the runtime-error / bytes frontier
    /// (bench/runtime.md): on 256² the linear lookup (Bevy) is best at 7 levels (last 4×4:
    /// 2×2 faces cost 13% at r = 1), Filament's at 6 (cmgen's own full chain to 1×1 measured
    /// 27–45% at r ≈ 1), Unity reads 7, Babylon a full chain. gltf, read by the same linear
    /// lookup as Bevy, goes down to 4×4 faces too (7 levels on 256²): against 6 levels (down to
    /// 8×8) the worst error over r ∈ [0.25, 1] falls on three of the four fixtures and over
    /// r ∈ [0.1, 0.25) on all four (10–78% → 3–37%), for 768 more bytes at RGBA16F.
    pub levels: usize,
    /// Default base face size of the specular chain.
    pub size: usize,
    /// Whether the engine's lookup fixes the level count: Unity reads mips 0–6 whatever the
    /// file holds, Babylon a full chain (prefilter refuses another), three none.
    pub levels_fixed: bool,
    /// The diffuse (irradiance) form the engine reads.
    pub diffuse: DiffuseForm,
    /// File names the engine expects.
    pub files: FileNames,
    /// A one-paragraph summary of how to load the outputs; the note written beside a run's
    /// outputs as [`NOTE_NAME`] is [`note::load_note`], built from the files the run wrote.
    pub note: &'static str,
}

impl Target {
    /// The name flags and RON keys use.
    pub fn name(self) -> &'static str {
        match self {
            Target::Gltf => "gltf",
            Target::Bevy => "bevy",
            Target::Filament => "filament",
            Target::Three => "three",
            Target::Babylon => "babylon",
            Target::Unity => "unity",
            Target::Custom => "custom",
        }
    }

    /// The engine's row of the table.
    pub fn spec(self) -> TargetSpec {
        match self {
            // KhronosGroup/glTF-Sample-Viewer `source/Renderer/shaders/ibl.glsl`: textureLod of
            // the GGX cube at the reflection direction itself (u_envRotation only turns the
            // environment on the user's request), lod = r·(mip count − 1); the Lambertian cube
            // is multiplied by the diffuse colour (E/π). KTX2 loaded by libktx
            // (`source/ResourceLoader/ktx.js`).
            Target::Gltf => TargetSpec {
                target: self,
                engine: "glTF-Sample-Viewer / glTF-IBL-Sampler",
                layout: Layout::Ktx2,
                format: PixelFormat::Rgba16f,
                zstd: None,
                orientation: Orientation::IDENTITY,
                lod: LodMapping::Linear,
                levels: 7,
                size: 256,
                levels_fixed: false,
                diffuse: DiffuseForm::IrradianceCube,
                files: FileNames {
                    specular: "prefilter",
                    irradiance: Some("irradiance"),
                    sh: None,
                    cube: "cube",
                },
                note: "glTF-Sample-Viewer / glTF-IBL-Sampler conventions: prefilter.ktx2 is the GGX chain (level l at roughness l/(N-1); sample with textureLod(cube, R, roughness * (mipCount - 1))), irradiance.ktx2 the Lambertian cube (E/pi; multiply by the diffuse colour), our frame unchanged.",
            },
            // bevyengine/bevy `crates/bevy_pbr/src/light_probe/environment_map.wesl`:
            // `radiance_level = perceptual_roughness * f32(light_probes.smallest_specular_mip_level_for_view)`
            // (mip count − 1) and "Cube maps are left-handed so we negate the z coordinate"
            // (`sample_dir.z = -sample_dir.z`) for both the specular and the diffuse lookups;
            // `out.diffuse = (FmsEms + kD) * radiances.irradiance` (no 1/π: an E/π cube).
            // Its shipped maps (`assets/environment_maps/pisa_*_rgb9e5_zstd.ktx2`) are KTX2
            // RGB9E5 + zstd, read by `crates/bevy_image/src/ktx2.rs`.
            Target::Bevy => TargetSpec {
                target: self,
                engine: "Bevy (EnvironmentMapLight)",
                layout: Layout::Ktx2,
                format: PixelFormat::Rgb9e5,
                zstd: Some(19),
                orientation: Orientation::FLIP_Z,
                lod: LodMapping::Linear,
                levels: 7,
                size: 256,
                levels_fixed: false,
                diffuse: DiffuseForm::IrradianceCube,
                files: FileNames {
                    specular: "specular_rgb9e5_zstd",
                    irradiance: Some("diffuse_rgb9e5_zstd"),
                    sh: None,
                    cube: "skybox_rgb9e5_zstd",
                },
                note: "Bevy: EnvironmentMapLight { diffuse_map: asset_server.load(\"diffuse_rgb9e5_zstd.ktx2\"), specular_map: asset_server.load(\"specular_rgb9e5_zstd.ktx2\"), intensity: 900.0, ..default() } (intensity in cd/m^2 per unit of the files, as Bevy's examples use; enable Bevy's `ktx2` and `zstd_rust` features). The cubes are stored with z negated, as Bevy samples them, so the environment shows as the source panorama; the chain's level l is at roughness l/(N-1), as Bevy reads it.",
            },
            // google/filament `shaders/src/surface_light_indirect.fs` (perceptualRoughnessToLod,
            // Irradiance_SphericalHarmonics), `tools/cmgen/src/cmgen.cpp` (KTX1 output with the
            // `sh` metadata, `_ibl.ktx` / `_skybox.ktx` names, R11F_G11F_B10F by default,
            // mirrored unless --no-mirror), `libs/ibl/src/CubemapUtils.cpp`
            // (equirectangularToCubemap: longitude atan2(x, z); mirrorCubemap: x negated).
            Target::Filament => TargetSpec {
                target: self,
                engine: "Filament (IndirectLight / Skybox)",
                layout: Layout::Ktx1,
                format: PixelFormat::B10g11r11,
                zstd: None,
                orientation: Orientation::TURN_Y_90,
                lod: LodMapping::Filament,
                levels: 6,
                size: 256,
                levels_fixed: false,
                diffuse: DiffuseForm::FilamentSh,
                files: FileNames {
                    specular: "env_ibl",
                    irradiance: None,
                    sh: Some("sh.txt"),
                    cube: "env_skybox",
                },
                note: "Filament: IndirectLight from env_ibl.ktx (ktxreader::Ktx1Reader::createTexture; its `sh` metadata holds the 9 pre-scaled irradiance coefficients, also in sh.txt as cmgen --sh-shader writes them: IndirectLight::Builder().reflections(tex).irradiance(3, sh)), Skybox from env_skybox.ktx. Level l is at cmgen's roughness 1 - sqrt(1 - l/(N-1)), which Filament's lookup lod = (N-1) r(2-r) lands on; oriented as cmgen orients the same panorama (our frame turned 90 degrees about +Y).",
            },
            // mrdoob/three.js `src/renderers/shaders/ShaderChunk/envmap_fragment.glsl.js`
            // (`textureCube( envMap, envMapRotation * vec3( flipEnvMap * reflectVec.x,
            // reflectVec.yz ) )`, flipEnvMap = −1 for CubeTexture), PMREMGenerator
            // (`src/extras/PMREMGenerator.js`) filters any environment itself, and
            // `examples/jsm/loaders/KTX2Loader.js` does not load float cubes: what we ship is
            // the environment cube (HDR faces for HDRCubeTextureLoader) and the LightProbe.
            Target::Three => TargetSpec {
                target: self,
                engine: "three.js (PMREMGenerator, LightProbe)",
                layout: Layout::Faces,
                format: PixelFormat::Rgba32f,
                zstd: None,
                orientation: Orientation::FLIP_X,
                lod: LodMapping::Pmrem,
                levels: 1,
                size: 256,
                levels_fixed: true,
                diffuse: DiffuseForm::ThreeLightProbe,
                files: FileNames {
                    specular: "cube",
                    irradiance: None,
                    sh: Some("LightProbe.json"),
                    cube: "cube",
                },
                note: "three.js: load the cube faces (px nx py ny pz nz, stored x-mirrored as three samples CubeTextures) as a CubeTexture and let PMREMGenerator.fromCubemap filter it (three does not read a prefiltered chain); add the diffuse probe with new THREE.ObjectLoader().parse(JSON.parse(LightProbe.json)) (a LightProbe: radiance SH in three's basis, frame unchanged).",
            },
            // BabylonJS/Babylon.js `packages/dev/core/src/Misc/environmentTextureTools.ts`
            // (the `.env` container), `Shaders/ShadersInclude/pbrBlockReflection.fx`
            // (getLodFromAlphaG × lodGenerationScale), `Materials/Textures/Filtering/
            // hdrFiltering.ts` (a full chain, α = 2^(l/0.8)/size); default scenes are
            // left-handed.
            Target::Babylon => TargetSpec {
                target: self,
                engine: "Babylon.js (CubeTexture from .env)",
                layout: Layout::Faces,
                format: PixelFormat::Rgba32f,
                zstd: None,
                orientation: babylon::ORIENTATION,
                lod: LodMapping::Babylon {
                    scale: lod::BABYLON_LOD_SCALE,
                },
                levels: 9,
                size: 256,
                levels_fixed: true,
                diffuse: DiffuseForm::BabylonManifest,
                files: FileNames {
                    specular: "environment",
                    irradiance: None,
                    sh: None,
                    cube: "environment",
                },
                note: "Babylon.js: scene.environmentTexture = CubeTexture.CreateFromPrefilteredData(\"environment.env\", scene) (a left-handed scene, Babylon's default; with scene.useRightHandedSystem use --target gltf orientation). Level l holds alpha = 2^(l/0.8)/size, what Babylon's lookup lod = 0.8 log2(size alpha) reads; the manifest carries the irradiance harmonics.",
            },
            // Unity-Technologies/Graphics `Packages/com.unity.render-pipelines.core/
            // ShaderLibrary/ImageBasedLighting.hlsl` (PerceptualRoughnessToMipmapLevel,
            // UNITY_SPECCUBE_LOD_STEPS 6: seven mips read), `SphericalHarmonics.hlsl` (basis
            // signs, PackSH); Unity is left-handed (z flipped).
            Target::Unity => TargetSpec {
                target: self,
                engine: "Unity (Cubemap asset / reflection probe, SphericalHarmonicsL2)",
                layout: Layout::Dds,
                format: PixelFormat::Rgba16f,
                zstd: None,
                orientation: Orientation::FLIP_Z,
                lod: LodMapping::Unity,
                levels: 7,
                size: 256,
                levels_fixed: true,
                diffuse: DiffuseForm::UnityShL2,
                files: FileNames {
                    specular: "specular",
                    irradiance: None,
                    sh: Some("SphericalHarmonicsL2.json"),
                    cube: "cube",
                },
                note: "Unity: import specular.dds as a Cubemap (Texture Shape: Cube, keep its mips, no 'Convolution' re-filtering) and assign it as a custom reflection probe / skybox cubemap; mip m holds the roughness Unity's lookup mip = 6 r(1.7 - 0.7 r) lands on (7 mips). SphericalHarmonicsL2.json holds the ambient probe as Unity's sh[rgb, i] (pre-multiplied, Unity's left-handed frame) and the packed unity_SHAr..unity_SHC.",
            },
            // Ours: the lookup is emitted beside the chain (lookup.glsl / .hlsl / .wgsl) and its
            // constants are in prefilter.json and the KTX2 key/value data
            // (docs/CUSTOM_LOOKUP.md); frame and files as gltf's.
            Target::Custom => TargetSpec {
                target: self,
                engine: "custom renderer (ibl custom lookup)",
                layout: Layout::Ktx2,
                format: PixelFormat::Rgba16f,
                zstd: None,
                orientation: Orientation::IDENTITY,
                lod: LodMapping::Custom {
                    alpha0: lod::CUSTOM_ALPHA0,
                },
                levels: 7,
                size: 256,
                levels_fixed: false,
                diffuse: DiffuseForm::IrradianceCube,
                files: FileNames {
                    specular: "prefilter",
                    irradiance: Some("irradiance"),
                    sh: None,
                    cube: "cube",
                },
                note: "Custom lookup: prefilter.ktx2 is a KTX2 RGBA16F cube chain, our frame (as gltf), whose ALPHA channel is part of the data (upload RGBA16F as stored, never convert it to RGB or compress it). Read it with the function in lookup.glsl / lookup.hlsl / lookup.wgsl (written beside it): lod = clamp(s * log2(1 + r*r/a0), 0, N-1), then TWO textureLod taps, levels l = min(floor(lod), N-2) and l + 1, blended by t = lod - l and corrected by their alpha (the kernel at the intervals' midpoints; the sampler's filter must be linear). The constants s, a0, N and this chain's power factors (IBL_LOOKUP_POWER: per probe, a uniform if one function serves several probes) are also in prefilter.json (\"custom_lookup\") and in the KTX2 key/value data (ibl.lookup.*); see docs/CUSTOM_LOOKUP.md. irradiance.ktx2 (irradiance --target custom) is the Lambertian cube (E/pi).",
            },
        }
    }

    /// Whether the engine's diffuse term samples our irradiance cube (E/π) rather than
    /// evaluating SH coefficients. Such engines show every texel of the cube, so `irradiance`
    /// fills it by exact cosine convolution by default: a 3-band SH cannot hold a sun (3.8%
    /// relative MAE on city, 6.8% on studio, worst texel 20–72%). Reads the cube:
    /// glTF-Sample-Viewer (KhronosGroup/glTF-Sample-Viewer `source/Renderer/shaders/ibl.glsl`,
    /// `getDiffuseLight` samples `u_LambertianEnvSampler`), Bevy
    /// (bevyengine/bevy `crates/bevy_pbr/src/light_probe/environment_map.wesl`, the
    /// `diffuse_map` sample), and our custom lookup (docs/CUSTOM_LOOKUP.md). Reads SH:
    /// Filament (google/filament `shaders/src/light_indirect.fs`), three.js `LightProbe`,
    /// Babylon's `.env` polynomial, Unity's SphericalHarmonicsL2 (docs/ENGINES.md).
    pub fn reads_diffuse_cube(self) -> bool {
        self.spec().diffuse == DiffuseForm::IrradianceCube
    }

    #[cfg(test)]
    /// Roughness the chain stores at each of its `levels` levels of base `size`.
    pub(crate) fn level_roughnesses(self, levels: usize, size: usize) -> Vec<f32> {
        self.spec().lod.level_roughnesses(levels, size)
    }

    /// The output encoding the target's bakes write when no --layout/--format is given: the
    /// container and format the engine loads as-is. `gltf`, the default target, keeps today's
    /// EXR faces in RGBA32F (the viewer's KTX2 RGBA16F is `--layout ktx2 --half`).
    pub fn encoding(self) -> ibl_core::output::Encoding {
        if self == Target::Gltf {
            return ibl_core::output::Encoding::default();
        }
        let s = self.spec();
        ibl_core::output::Encoding {
            layout: s.layout,
            format: s.format,
            zstd: s.zstd,
            ..Default::default()
        }
    }

    /// `encoding` (the flags resolved over [`Target::encoding`]) if the engine's own loader
    /// takes it; otherwise a one-line reason naming the engine's file that refuses it.
    ///
    /// Filament: its KTX1 reader maps glType to a pixel type through `toPixelDataType`
    /// (google/filament `libs/ktxreader/src/Ktx1Reader.cpp`), which knows UNSIGNED_BYTE,
    /// UNSIGNED_SHORT, HALF_FLOAT, FLOAT and R11F_G11F_B10F only; the packed RGB9E5 type
    /// (UNSIGNED_INT_5_9_9_9_REV, 0x8C3E) becomes 0xff, and Filament has no pixel type for it at
    /// all (`PixelDataType` in `filament/backend/include/backend/DriverEnums.h`), so no header
    /// makes packed RGB9E5 texels loadable: `setImage` aborts ("The combination of internal
    /// format … is not supported"). Refused before any work.
    pub fn check_encoding(
        self,
        encoding: ibl_core::output::Encoding,
    ) -> Result<ibl_core::output::Encoding, ibl_core::Error> {
        if self == Target::Filament
            && encoding.layout == Layout::Ktx1
            && encoding.format == PixelFormat::Rgb9e5
        {
            return Err(ibl_core::Error::param(
                "--target filament cannot take --format rgb9e5 in KTX1: Filament's KTX1 reader (google/filament libs/ktxreader/src/Ktx1Reader.cpp, toPixelDataType) has no pixel type for packed RGB9E5 and aborts on it; use --format b10g11r11 (cmgen's, the default, same 4 bytes a texel) or rgba16f",
            ));
        }
        Ok(encoding)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_engines_that_sample_the_diffuse_cube_are_the_cube_targets() {
        let cube: Vec<&str> = ALL_TARGETS
            .iter()
            .filter(|t| t.reads_diffuse_cube())
            .map(|t| t.name())
            .collect();
        assert_eq!(cube, ["gltf", "bevy", "custom"]);
        for t in ALL_TARGETS {
            // A cube reader gets an irradiance cube file; an SH reader gets its SH file.
            assert_eq!(
                t.reads_diffuse_cube(),
                t.spec().files.irradiance.is_some(),
                "{t:?}"
            );
        }
    }

    #[test]
    fn filament_refuses_packed_rgb9e5_in_ktx1_only() {
        use ibl_core::output::Encoding;
        let enc = |layout, format| Encoding {
            layout,
            format,
            ..Default::default()
        };
        let e = Target::Filament
            .check_encoding(enc(Layout::Ktx1, PixelFormat::Rgb9e5))
            .unwrap_err()
            .to_string();
        assert!(e.contains("Ktx1Reader.cpp") && e.contains("rgb9e5"), "{e}");
        for f in [
            PixelFormat::B10g11r11,
            PixelFormat::Rgba16f,
            PixelFormat::Rgba32f,
        ] {
            assert!(Target::Filament
                .check_encoding(enc(Layout::Ktx1, f))
                .is_ok());
        }
        // Filament's default passes; RGB9E5 stays Bevy's default and anyone else's choice.
        assert!(Target::Filament
            .check_encoding(Target::Filament.encoding())
            .is_ok());
        for t in ALL_TARGETS {
            if t != Target::Filament {
                assert!(t
                    .check_encoding(enc(Layout::Ktx1, PixelFormat::Rgb9e5))
                    .is_ok());
            }
        }
    }
    use glam::Vec3;
    use ibl_core::cube::{texel_direction, Cubemap, Face};
    use std::f32::consts::PI;

    #[test]
    fn names_round_trip_through_serde_and_clap() {
        use clap::ValueEnum;
        for t in ALL_TARGETS {
            let j = serde_json::to_string(&t).unwrap();
            assert_eq!(j, format!("\"{}\"", t.name()));
            let back: Target = ron::from_str(t.name()).unwrap();
            assert_eq!(back, t);
            assert_eq!(Target::from_str(t.name(), false).unwrap(), t);
            assert_eq!(t.spec().target, t);
        }
        assert_eq!(Target::default(), Target::Gltf);
        assert!(ron::from_str::<Target>("gtlf").is_err());
    }

    /// A smooth panorama P(u, v), periodic in u, distinguishing every direction.
    fn panorama(u: f32, v: f32) -> [f32; 3] {
        let (a, b) = (2.0 * PI * u, PI * v);
        [
            2.0 + a.sin() * b.sin(),
            2.0 + a.cos() * b.sin() + 0.3 * b.cos(),
            2.0 + (2.0 * a).sin() * b.sin() * b.sin(),
        ]
    }

    /// Our mapping (docs/CONVENTIONS.md): u = 0.5 + atan2(z, x)/2π, v = acos(y)/π.
    fn ours_uv(d: Vec3) -> (f32, f32) {
        let d = d.normalize();
        (
            0.5 + d.z.atan2(d.x) / (2.0 * PI),
            d.y.clamp(-1.0, 1.0).acos() / PI,
        )
    }

    fn close(a: [f32; 3], b: [f32; 3]) -> bool {
        (0..3).all(|k| (a[k] - b[k]).abs() < 2e-4)
    }

    /// For each engine: the file we write, read by the engine's own sampling of world
    /// direction w, shows what that engine should show at w.
    #[test]
    fn each_engine_reads_the_intended_radiance_for_a_world_direction() {
        let n = 8;
        let ours = Cubemap::from_fn(n, |d| {
            let (u, v) = ours_uv(d);
            panorama(u, v)
        });
        let file = |t: Target| t.spec().orientation.apply(&ours);
        for face in Face::ALL {
            for j in 0..n {
                for i in 0..n {
                    let w = texel_direction(face, i, j, n);
                    let (u, v) = ours_uv(w);
                    let want = panorama(u, v);
                    // glTF viewer: textureLod(u_GGXEnvSampler, reflection) — the world direction.
                    let g = file(Target::Gltf);
                    assert!(close(g.sample_bilinear(w), want));
                    // Bevy: sample_dir.z = -sample_dir.z (environment_map.wesl).
                    let s = Vec3::new(w.x, w.y, -w.z);
                    assert!(
                        close(file(Target::Bevy).sample_bilinear(s), want),
                        "bevy {w:?}"
                    );
                    // three: vec3(flipEnvMap * x, y, z), flipEnvMap = -1 (envmap_fragment);
                    // three's equirectUv is our mapping, so it shows the panorama like ours.
                    let s = Vec3::new(-w.x, w.y, w.z);
                    assert!(
                        close(file(Target::Three).sample_bilinear(s), want),
                        "three {w:?}"
                    );
                    // Unity (left-handed): world u ↔ our (u.x, u.y, −u.z).
                    let uw = Vec3::new(w.x, w.y, -w.z);
                    assert!(close(file(Target::Unity).sample_bilinear(uw), want));
                    // Babylon: its own panorama route puts our direction (s.z, s.y, s.x) at
                    // the file direction s (babylon::ORIENTATION, measured by rendering).
                    let s = Vec3::new(w.z, w.y, w.x);
                    assert!(
                        close(file(Target::Babylon).sample_bilinear(s), want),
                        "babylon"
                    );
                    // Filament samples the file at the world direction; what cmgen puts there
                    // is the panorama at its mirrored longitude: mirrorCubemap reads
                    // (−x, y, z), equirectangularToCubemap maps s to
                    // u = (atan2(s.x, s.z)/π + 1)/2, v = (1 − asin(s.y)·2/π)/2.
                    let s = Vec3::new(-w.x, w.y, w.z).normalize();
                    let cu = (s.x.atan2(s.z) / PI + 1.0) * 0.5;
                    let cv = (1.0 - s.y.asin() * 2.0 / PI) * 0.5;
                    let f = file(Target::Filament).texel(face, i, j);
                    assert!(close(f, panorama(cu, cv)), "filament {w:?} {f:?}");
                }
            }
        }
    }

    #[test]
    fn table_is_consistent() {
        for t in ALL_TARGETS {
            let s = t.spec();
            assert!(s.levels >= 1 && s.size.is_power_of_two());
            assert!(s.levels <= s.size.trailing_zeros() as usize + 1, "{t:?}");
            assert!(!s.note.is_empty());
            let r = t.level_roughnesses(s.levels, s.size);
            assert_eq!(r.len(), s.levels);
        }
        // Unity reads mips 0..=6; Babylon reads a full chain.
        assert_eq!(Target::Unity.spec().levels, 7);
        let b = Target::Babylon.spec();
        assert_eq!(b.levels, b.size.trailing_zeros() as usize + 1);
    }
}
