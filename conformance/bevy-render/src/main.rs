//! Bevy's own renderer draws the scene "sphere-rows v1" (crates/ibl-render/src/scene.rs) lit by
//! our `--target bevy` files, offscreen (no window, no surface: wgpu on whatever Vulkan ICD is
//! present, here Mesa's llvmpipe), reads the linear float image back and writes it as PFM.
//!
//! Usage: `bevy-render SPECULAR.ktx2 DIFFUSE.ktx2 OUT.pfm [INTENSITY]`
//!
//! The scene is set up as the `--target bevy` LOAD.txt snippet says (EnvironmentMapLight on the
//! camera, `intensity` as the note gives it, default 900.0) and, so the image is in the files'
//! own units like the reference render, the camera's exposure is set to cancel the intensity
//! (bevyengine/bevy `crates/bevy_camera/src/camera.rs` `Exposure::exposure` = 2^−ev100 / 1.2).
//! Everything else the image goes through is switched off: no tonemapping, no MSAA, no dither,
//! no ambient light (Bevy adds `GlobalAmbientLight`, 80 cd/m² by default, on top of the
//! environment map: `crates/bevy_pbr/src/render/pbr_functions.wgsl`, `ambient_light`).
//!
//! Exit code 0 with the PFM written; 1 with a one-line reason (files not loading, no adapter,
//! a black render).

use bevy::{
    app::{AppExit, ScheduleRunnerPlugin},
    asset::{AssetPlugin, LoadState},
    camera::{Exposure, Hdr, RenderTarget, ScalingMode},
    core_pipeline::tonemapping::{DebandDither, Tonemapping},
    light::GlobalAmbientLight,
    prelude::*,
    render::{
        gpu_readback::{Readback, ReadbackComplete},
        render_resource::{TextureFormat, TextureUsages},
        view::Msaa,
    },
    window::{ExitCondition, WindowPlugin},
};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The contract's image size (crates/ibl-render/src/scene.rs `WIDTH`, `HEIGHT`).
const WIDTH: u32 = 768;
const HEIGHT: u32 = 256;
/// Frames rendered after the files are loaded before the image is read (Bevy compiles its
/// pipelines in the background: the first frames after loading can lack the spheres).
const SETTLE_FRAMES: u32 = 8;
/// Readbacks after which the image is taken even if consecutive ones still differ. On llvmpipe
/// under load Bevy's background pipeline compilation took more than 60 frames (1 ms apart) for
/// the spheres to appear; a frame costs little, so the budget is generous.
const MAX_READBACKS: u32 = 2000;
/// Frames after which the run gives up waiting for the files to load.
const LOAD_TIMEOUT_FRAMES: u32 = 3000;

#[derive(Resource)]
struct Job {
    specular: Handle<Image>,
    diffuse: Handle<Image>,
    target: Handle<Image>,
    out: PathBuf,
    loaded_at: Option<u32>,
    frame: u32,
    readbacks: u32,
    previous: Option<Vec<u8>>,
    reading: bool,
}

fn main() -> AppExit {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if !(3..=4).contains(&args.len()) {
        eprintln!("usage: bevy-render SPECULAR.ktx2 DIFFUSE.ktx2 OUT.pfm [INTENSITY]");
        return AppExit::from_code(2);
    }
    let intensity: f32 = match args.get(3).map(|s| s.parse()) {
        None => 900.0,
        Some(Ok(v)) if v > 0.0 && f32::is_finite(v) => v,
        Some(_) => {
            eprintln!(
                "bevy-render: INTENSITY {} is not a positive number",
                args[3]
            );
            return AppExit::from_code(2);
        }
    };
    let mut assets = Vec::new();
    for a in &args[..2] {
        match std::fs::canonicalize(a) {
            Ok(p) => assets.push(p),
            Err(e) => {
                eprintln!("bevy-render: {a}: {e}");
                return AppExit::from_code(1);
            }
        }
    }
    let out = PathBuf::from(&args[2]);
    App::new()
        .add_plugins((
            DefaultPlugins
                .set(WindowPlugin {
                    primary_window: None,
                    exit_condition: ExitCondition::DontExit,
                    ..default()
                })
                // Asset paths are given relative to "/" (the files' absolute paths).
                .set(AssetPlugin {
                    file_path: "/".into(),
                    ..default()
                }),
            // No winit: the app is driven by the schedule runner (as Bevy's headless_renderer
            // example does).
            ScheduleRunnerPlugin::run_loop(Duration::from_millis(1)),
        ))
        .insert_resource(GlobalAmbientLight {
            brightness: 0.0,
            ..default()
        })
        .insert_resource(ClearColor(Color::BLACK))
        .insert_resource(Args {
            specular: assets[0].clone(),
            diffuse: assets[1].clone(),
            out,
            intensity,
        })
        .add_systems(Startup, setup)
        .add_systems(Update, step)
        .run()
}

#[derive(Resource)]
struct Args {
    specular: PathBuf,
    diffuse: PathBuf,
    out: PathBuf,
    intensity: f32,
}

/// An absolute path as an asset path under the "/" root.
fn asset_path(p: &Path) -> String {
    p.to_string_lossy().trim_start_matches('/').to_string()
}

fn setup(
    mut commands: Commands,
    args: Res<Args>,
    asset_server: Res<AssetServer>,
    mut images: ResMut<Assets<Image>>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
) {
    let specular: Handle<Image> = asset_server.load(asset_path(&args.specular));
    let diffuse: Handle<Image> = asset_server.load(asset_path(&args.diffuse));

    let mut target = Image::new_target_texture(WIDTH, HEIGHT, TextureFormat::Rgba32Float, None);
    target.texture_descriptor.usage |= TextureUsages::COPY_SRC;
    let target = images.add(target);

    // Contract camera: orthographic, at +Z looking at −Z, x ∈ [−6, 6], y ∈ [−2, 2].
    commands.spawn((
        Camera3d::default(),
        Camera::default(),
        RenderTarget::from(target.clone()),
        Projection::Orthographic(OrthographicProjection {
            scaling_mode: ScalingMode::Fixed {
                width: 12.0,
                height: 4.0,
            },
            near: 0.1,
            far: 100.0,
            ..OrthographicProjection::default_3d()
        }),
        Transform::from_xyz(0.0, 0.0, 10.0).looking_at(Vec3::ZERO, Vec3::Y),
        Hdr,
        Tonemapping::None,
        DebandDither::Disabled,
        Msaa::Off,
        // Exposure 1: ev100 = log2(intensity / 1.2) cancels the intensity (see the file's doc).
        Exposure {
            ev100: (args.intensity / 1.2).log2(),
        },
        // As the --target bevy LOAD.txt snippet inserts it.
        EnvironmentMapLight {
            diffuse_map: diffuse.clone(),
            specular_map: specular.clone(),
            intensity: args.intensity,
            ..default()
        },
    ));

    // Two rows of six spheres (radius 0.9) at x = −5, −3 … 5; metallic at y = +1, dielectric
    // (F0 = 0.04: Bevy's default reflectance 0.5 → 0.16·0.5²) at y = −1; roughness i/5.
    let mesh = meshes.add(Sphere::new(0.9).mesh().uv(192, 96));
    for (row, (y, metallic)) in [(1.0, 1.0), (-1.0, 0.0)].into_iter().enumerate() {
        for i in 0..6 {
            let material = materials.add(StandardMaterial {
                base_color: Color::WHITE,
                metallic,
                perceptual_roughness: i as f32 / 5.0,
                reflectance: 0.5,
                ..default()
            });
            commands.spawn((
                Mesh3d(mesh.clone()),
                MeshMaterial3d(material),
                Transform::from_xyz(-5.0 + 2.0 * i as f32, y, 0.0),
                Name::new(format!("sphere {}", row * 6 + i)),
            ));
        }
    }
    commands.insert_resource(Job {
        specular,
        diffuse,
        target,
        out: args.out.clone(),
        loaded_at: None,
        frame: 0,
        readbacks: 0,
        previous: None,
        reading: false,
    });
}

fn step(
    mut commands: Commands,
    mut job: ResMut<Job>,
    asset_server: Res<AssetServer>,
    mut exit: MessageWriter<AppExit>,
) {
    job.frame += 1;
    if job.loaded_at.is_none() {
        for (name, h) in [("specular", &job.specular), ("diffuse", &job.diffuse)] {
            if let LoadState::Failed(e) = asset_server.load_state(h) {
                eprintln!("bevy-render: Bevy did not load the {name} map: {e}");
                exit.write(AppExit::from_code(1));
                return;
            }
        }
        if asset_server.is_loaded_with_dependencies(&job.specular)
            && asset_server.is_loaded_with_dependencies(&job.diffuse)
        {
            job.loaded_at = Some(job.frame);
        } else if job.frame > LOAD_TIMEOUT_FRAMES {
            eprintln!("bevy-render: the maps did not load in {LOAD_TIMEOUT_FRAMES} frames");
            exit.write(AppExit::from_code(1));
        }
        return;
    }
    if !job.reading && job.frame >= job.loaded_at.unwrap_or(0) + SETTLE_FRAMES {
        job.reading = true;
        commands
            .spawn(Readback::texture(job.target.clone()))
            .observe(on_readback);
    }
}

/// Each frame's read-back: the image is taken once two consecutive ones agree (pipelines
/// compiled, maps uploaded) and every sphere's centre is lit.
fn on_readback(
    event: On<ReadbackComplete>,
    mut job: ResMut<Job>,
    mut exit: MessageWriter<AppExit>,
) {
    let data: &[u8] = &event.data;
    let expected = (WIDTH * HEIGHT * 16) as usize;
    if data.len() != expected {
        eprintln!(
            "bevy-render: read back {} bytes, expected {expected}",
            data.len()
        );
        exit.write(AppExit::from_code(1));
        return;
    }
    job.readbacks += 1;
    let pixels: Vec<f32> = data
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    // Centres of the twelve spheres (crates/ibl-render/src/scene.rs `centre_pixel`).
    let dark: Vec<usize> = (0..12)
        .filter(|&s| {
            let (col, row) = (s % 6, s / 6);
            let px = (((-5.0 + 2.0 * col as f64) + 6.0) * 64.0) as usize;
            let py = ((2.0 - if row == 0 { 1.0 } else { -1.0 }) * 64.0) as usize;
            let i = 4 * (py * WIDTH as usize + px);
            !pixels[i..i + 3].iter().any(|&v| v > 0.0)
        })
        .collect();
    let lit = dark.is_empty();
    let stable = job.previous.as_deref() == Some(data);
    job.previous = Some(data.to_vec());
    if !(lit && stable) && job.readbacks < MAX_READBACKS {
        return;
    }
    if !lit {
        eprintln!(
            "bevy-render: the centres of spheres {dark:?} are black after {} frames",
            job.frame
        );
        exit.write(AppExit::from_code(1));
        return;
    }
    match write_pfm(&job.out, &pixels) {
        Ok(()) => {
            println!(
                "bevy-render: wrote {} ({WIDTH}x{HEIGHT}, frame {}, readback {}{})",
                job.out.display(),
                job.frame,
                job.readbacks,
                if stable { "" } else { ", not yet stable" }
            );
            exit.write(AppExit::Success);
        }
        Err(e) => {
            eprintln!("bevy-render: {}: {e}", job.out.display());
            exit.write(AppExit::from_code(1));
        }
    }
}

/// PFM (rows bottom first, little-endian RGB floats), written atomically (temp + rename).
fn write_pfm(out: &Path, rgba: &[f32]) -> std::io::Result<()> {
    let (w, h) = (WIDTH as usize, HEIGHT as usize);
    let mut bytes = format!("PF\n{w} {h}\n-1.0\n").into_bytes();
    for row in (0..h).rev() {
        for px in 0..w {
            let i = 4 * (row * w + px);
            for c in 0..3 {
                bytes.extend_from_slice(&rgba[i + c].to_le_bytes());
            }
        }
    }
    let tmp = out.with_extension("pfm.tmp");
    std::fs::write(&tmp, &bytes)?;
    std::fs::rename(&tmp, out)
}
