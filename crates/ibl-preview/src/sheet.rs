//! The contact sheet: one labelled row per asset, every tile scaled to a common height,
//! HDR tiles tone-mapped with one exposure so rows compare.

use crate::assets::Asset;
use crate::cross::{fit_height, horizontal_cross};
use crate::font::{draw_text, text_height, text_width};
use crate::tonemap::{display, exposure_scale, log_average_luminance};
use ibl_core::{Cubemap, Image};

/// Labels are the 5×7 font upscaled ×2.
pub(crate) const LABEL_SCALE: usize = 2;
const MARGIN: usize = 16;
const GAP: usize = 20;
const BACKGROUND: [f32; 3] = [0.13, 0.13, 0.14];
const TEXT: [f32; 3] = [0.92, 0.92, 0.92];
const TITLE: [f32; 3] = [1.0, 0.8, 0.35];

/// A display-ready picture (RGBA, display values in [0, 1]; alpha 0 shows the background)
/// and its caption.
pub struct Tile {
    /// Text drawn under the picture.
    pub caption: String,
    /// The picture (RGBA, display values).
    pub image: Image,
}

/// A titled row of tiles.
pub struct Row {
    /// Text drawn left of the row.
    pub title: String,
    /// The pictures, left to right.
    pub tiles: Vec<Tile>,
}

/// How the HDR tiles are exposed.
#[derive(Clone, Copy, Debug)]
pub struct Exposure {
    /// Log-average luminance of the environment the exposure is taken from.
    pub mean_luminance: f32,
    /// The linear scale applied before the tone curve.
    pub scale: f32,
}

/// The exposure for a set of assets: from the environment cube if there is one, else from
/// the first cube (level 0 of a chain, or the irradiance), shifted by `ev` stops.
pub fn exposure_for(assets: &[Asset], ev: f32) -> Exposure {
    let cube = assets.iter().find_map(|a| match a {
        Asset::Environment { cube, .. } | Asset::Irradiance { cube, .. } => Some(cube),
        Asset::Prefiltered { mips, .. } => mips.levels.first(),
        Asset::Lut { .. } => None,
    });
    let mean = cube.map_or(1.0, log_average_luminance);
    Exposure {
        mean_luminance: mean,
        scale: exposure_scale(mean, ev),
    }
}

fn tone_mapped_cross(cube: &Cubemap, scale: f32, height: usize) -> Image {
    let mut img = fit_height(&horizontal_cross(cube), height);
    for t in img.data.chunks_exact_mut(4) {
        let d = display([t[0], t[1], t[2]], scale);
        t[..3].copy_from_slice(&d);
    }
    img
}

/// A table shown as stored (R = A, G = B, clamped to [0, 1], no curve), with B zeroed when
/// the table has fewer channels.
fn lut_tile(image: &Image, height: usize) -> Image {
    let mut rgba = Image::new(image.width, image.height, 4);
    for y in 0..image.height {
        for x in 0..image.width {
            let s = image.texel(x, y);
            let t = rgba.texel_mut(x, y);
            for (c, v) in t[..3].iter_mut().enumerate() {
                *v = s.get(c).copied().unwrap_or(0.0).clamp(0.0, 1.0);
            }
            t[3] = 1.0;
        }
    }
    fit_height(&rgba, height)
}

fn file_label(path: &std::path::Path) -> String {
    path.display().to_string()
}

/// One row per asset, tiles `height` pixels tall.
pub fn rows(assets: &[Asset], exposure: Exposure, height: usize) -> Vec<Row> {
    let s = exposure.scale;
    assets
        .iter()
        .map(|a| match a {
            Asset::Environment { path, cube } => Row {
                title: format!("environment  {}", file_label(path)),
                tiles: vec![Tile {
                    caption: format!("cube {0}×{0}", cube.size),
                    image: tone_mapped_cross(cube, s, height),
                }],
            },
            Asset::Prefiltered {
                path,
                mips,
                roughness,
            } => Row {
                title: format!("prefiltered GGX  {}", file_label(path)),
                tiles: mips
                    .levels
                    .iter()
                    .enumerate()
                    .map(|(l, cube)| Tile {
                        caption: match roughness {
                            Some(r) => format!("level {l}, r = {:.2} ({}²)", r[l], cube.size),
                            None => format!("level {l} ({}²)", cube.size),
                        },
                        image: tone_mapped_cross(cube, s, height),
                    })
                    .collect(),
            },
            Asset::Irradiance { path, cube } => Row {
                title: format!("irradiance E/pi  {}", file_label(path)),
                tiles: vec![Tile {
                    caption: format!("cube {0}×{0}", cube.size),
                    image: tone_mapped_cross(cube, s, height),
                }],
            },
            Asset::Lut { path, image } => Row {
                title: format!("LUT  {}", file_label(path)),
                tiles: vec![Tile {
                    caption: format!(
                        "{}×{}  R = A, G = B; x = n·v, y = r",
                        image.width, image.height
                    ),
                    image: lut_tile(image, height),
                }],
            },
        })
        .collect()
}

/// The scene "sphere-rows v1" is drawn this many times smaller on the sheet (384×128): the
/// reference's cost falls 4× and the demo stays quick.
pub const SPHERE_SCALE: usize = 2;

/// A render (linear RGB) as an RGBA tile of display values, `height` pixels tall.
fn render_tile(img: &Image, scale: f32, height: usize) -> Image {
    let mut rgba = Image::new(img.width, img.height, 4);
    for y in 0..img.height {
        for x in 0..img.width {
            let d = display(img.rgb(x, y), scale);
            rgba.texel_mut(x, y)
                .copy_from_slice(&[d[0], d[1], d[2], 1.0]);
        }
    }
    fit_height(&rgba, height)
}

/// The sphere rows of the sheet (issue 22, item 7): the scene "sphere-rows v1" lit by the
/// baked probe as the default target (gltf) reads it — lod = r·(N − 1), bilinear and seamless
/// within a level, linear between levels (`ibl_render::ChainLookup`), the irradiance cube read
/// bilinearly — beside the reference render (the exact GGX kernel and E/π from the probe's
/// environment cube, `ibl_render::Lighting`), both with glTF's BRDF terms. None when the
/// assets hold no environment cube or no prefiltered chain. Also returns the comparison.
pub fn sphere_rows(
    assets: &[Asset],
    exposure: Exposure,
    height: usize,
    progress: &dyn ibl_core::progress::Progress,
) -> Option<(Vec<Row>, ibl_render::compare::Comparison)> {
    use ibl_render::{render_lit, ChainLookup, Engine, Lighting, ALL_SPHERES};
    let env = assets.iter().find_map(|a| match a {
        Asset::Environment { cube, .. } => Some(cube),
        _ => None,
    })?;
    let mips = assets.iter().find_map(|a| match a {
        Asset::Prefiltered { mips, .. } => Some(mips),
        _ => None,
    })?;
    let irradiance = assets.iter().find_map(|a| match a {
        Asset::Irradiance { cube, .. } => Some(cube.clone()),
        _ => None,
    });
    // A 32² E/π cube (0.08% mean, 1.2% worst on city_512 against the brute force; the 64² of
    // the reference proper would cost the demo seconds).
    let lighting = Lighting::with_irradiance_size(
        &ibl_core::envmap::Environment::Cube(env.clone()),
        32,
        progress,
    );
    let reference = render_lit(
        &lighting,
        Engine::Gltf,
        &ALL_SPHERES,
        SPHERE_SCALE,
        progress,
    );
    let lookup = ChainLookup::new(mips, ibl_target::Target::Gltf.spec().lod, irradiance);
    let baked = render_lit(&lookup, Engine::Gltf, &ALL_SPHERES, SPHERE_SCALE, progress);
    let c = ibl_render::compare::compare_scaled(&baked, &reference, SPHERE_SCALE).ok()?;
    let rows = vec![Row {
        title: format!(
            "spheres, glTF BRDF (metal above, dielectric below, r = 0...1): the bake as glTF reads it against the reference, mean error metal mirror {:.1}%, metal rough {:.1}%, dielectric rough {:.1}%",
            100.0 * c.metal_mirror,
            100.0 * c.metal_rough,
            100.0 * c.dielectric_rough
        ),
        tiles: vec![
            Tile {
                caption: "reference (exact kernel, E/pi)".to_string(),
                image: render_tile(&reference, exposure.scale, height),
            },
            Tile {
                caption: "baked chain, glTF lookup".to_string(),
                image: render_tile(&baked, exposure.scale, height),
            },
        ],
    }];
    Some((rows, c))
}

/// Lays the rows out on one RGB image of display values (title, then the tiles side by side
/// with their captions below).
pub fn compose(rows: &[Row], footer: &str) -> Image {
    let line = text_height(LABEL_SCALE);
    let row_width = |r: &Row| {
        let tiles: usize = r
            .tiles
            .iter()
            .map(|t| t.image.width.max(text_width(&t.caption, LABEL_SCALE)) + GAP)
            .sum();
        tiles
            .saturating_sub(GAP)
            .max(text_width(&r.title, LABEL_SCALE))
    };
    let row_height = |r: &Row| {
        let tile = r.tiles.iter().map(|t| t.image.height).max().unwrap_or(0);
        line + GAP / 2 + tile + GAP / 2 + line
    };
    let width = 2 * MARGIN
        + rows
            .iter()
            .map(row_width)
            .chain([text_width(footer, LABEL_SCALE)])
            .max()
            .unwrap_or(0);
    let height = 2 * MARGIN + rows.iter().map(|r| row_height(r) + 2 * GAP).sum::<usize>() + line;
    let mut img = Image::new(width, height, 3);
    for t in img.data.chunks_exact_mut(3) {
        t.copy_from_slice(&BACKGROUND);
    }
    let mut y = MARGIN;
    for r in rows {
        draw_text(&mut img, MARGIN, y, &r.title, LABEL_SCALE, TITLE);
        let top = y + line + GAP / 2;
        let tile_h = r.tiles.iter().map(|t| t.image.height).max().unwrap_or(0);
        let mut x = MARGIN;
        for t in &r.tiles {
            blit(&mut img, &t.image, x, top);
            draw_text(
                &mut img,
                x,
                top + tile_h + GAP / 2,
                &t.caption,
                LABEL_SCALE,
                TEXT,
            );
            x += t.image.width.max(text_width(&t.caption, LABEL_SCALE)) + GAP;
        }
        y += row_height(r) + 2 * GAP;
    }
    draw_text(&mut img, MARGIN, y, footer, LABEL_SCALE, TEXT);
    img
}

/// Alpha-blends an RGBA tile onto the RGB sheet at (x, y).
fn blit(dst: &mut Image, src: &Image, x: usize, y: usize) {
    for j in 0..src.height {
        for i in 0..src.width {
            let s = src.texel(i, j);
            let a = s[3].clamp(0.0, 1.0);
            let d = dst.texel_mut(x + i, y + j);
            for (d, s) in d.iter_mut().zip(&s[..3]) {
                *d = *d * (1.0 - a) + s * a;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ibl_core::CubeMips;
    use std::path::PathBuf;

    #[test]
    fn sheet_has_a_row_per_asset_and_a_tile_per_level() {
        let env = Cubemap::constant(8, [2.0, 2.0, 2.0]);
        let mips = CubeMips {
            levels: vec![
                Cubemap::constant(8, [2.0; 3]),
                Cubemap::constant(4, [2.0; 3]),
            ],
        };
        let assets = vec![
            Asset::Environment {
                path: PathBuf::from("cube"),
                cube: env,
            },
            Asset::Prefiltered {
                path: PathBuf::from("prefiltered"),
                mips,
                roughness: Some(vec![0.0, 1.0]),
            },
        ];
        let exposure = exposure_for(&assets, 0.0);
        assert!((exposure.scale * 2.0 - crate::tonemap::KEY).abs() < 1e-4);
        let rows = rows(&assets, exposure, 48);
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[1].tiles.len(), 2);
        assert_eq!(rows[1].tiles[1].caption, "level 1, r = 1.00 (4²)");
        // Every tile is scaled to the common height, crosses keep 4:3.
        for t in rows.iter().flat_map(|r| &r.tiles) {
            assert_eq!((t.image.width, t.image.height), (64, 48));
        }
        // The constant environment shows as one grey: the tone-mapped key value.
        let grey = display([crate::tonemap::KEY; 3], 1.0)[0];
        let face = rows[0].tiles[0].image.texel(24, 24);
        assert!((face[0] - grey).abs() < 1e-5 && face[3] == 1.0);
        let sheet = compose(&rows, "footer");
        assert!(sheet.width >= 2 * MARGIN + 64 + GAP + 64);
        // A face texel of the first row, at its place on the sheet.
        let top = MARGIN + text_height(LABEL_SCALE) + GAP / 2;
        assert!((sheet.texel(MARGIN + 24, top + 24)[0] - grey).abs() < 1e-5);
        // An empty cell of the cross shows the background.
        assert_eq!(sheet.texel(MARGIN + 2, top + 2), &BACKGROUND);
    }
}
