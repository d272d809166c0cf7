//! Bevy's own loader reads what the bakes write: `bevy_image`'s KTX2 loader (with zstd) and DDS
//! loader, exactly as `AssetServer` calls them for a `.ktx2` / `.dds` environment map.
//!
//! Usage: `bevy-conformance FILE:FORMAT:LEVELS...` (FORMAT as `--format` names it). For each
//! file: the wgpu texture format Bevy picks, the mip count, six array layers viewed as a cube,
//! and the data size. Prints one line per check and "N passed, N failed" last.

use bevy_asset::RenderAssetUsages;
use bevy_image::{CompressedImageFormats, Image, ImageSampler, ImageType};
use std::process::ExitCode;

fn wgpu_format(name: &str) -> Option<&'static str> {
    Some(match name {
        "rgba32f" => "Rgba32Float",
        "rgba16f" => "Rgba16Float",
        "rgb9e5" => "Rgb9e5Ufloat",
        "b10g11r11" => "Rg11b10Ufloat",
        "bc6h" => "Bc6hRgbUfloat",
        _ => return None,
    })
}

fn main() -> ExitCode {
    let (mut passed, mut failed) = (0, 0);
    let mut check = |ok: bool, what: String| {
        if ok {
            passed += 1;
            println!("ok   {what}");
        } else {
            failed += 1;
            println!("FAIL {what}");
        }
    };
    for arg in std::env::args().skip(1) {
        let mut parts = arg.rsplitn(3, ':');
        let (levels, format, path) = (parts.next(), parts.next(), parts.next());
        let (Some(levels), Some(format), Some(path)) = (levels, format, path) else {
            eprintln!("bad argument {arg}: want FILE:FORMAT:LEVELS");
            return ExitCode::from(2);
        };
        let levels: u32 = levels.parse().expect("levels");
        let ext = path.rsplit('.').next().unwrap_or("");
        let bytes = match std::fs::read(path) {
            Ok(b) => b,
            Err(e) => {
                check(false, format!("{path}: {e}"));
                continue;
            }
        };
        let image = Image::from_buffer(
            &bytes,
            ImageType::Extension(ext),
            CompressedImageFormats::BC,
            false,
            ImageSampler::Default,
            RenderAssetUsages::default(),
        );
        let image = match image {
            Ok(i) => i,
            Err(e) => {
                check(false, format!("{path}: bevy_image refused it: {e}"));
                continue;
            }
        };
        let d = &image.texture_descriptor;
        let got = format!("{:?}", d.format);
        check(
            Some(got.as_str()) == wgpu_format(format),
            format!(
                "{path}: Bevy reads it as {got} (want {:?})",
                wgpu_format(format)
            ),
        );
        check(
            d.mip_level_count == levels,
            format!("{path}: {} mips (want {levels})", d.mip_level_count),
        );
        check(
            d.size.depth_or_array_layers == 6,
            format!("{path}: {} array layers", d.size.depth_or_array_layers),
        );
        let view = image
            .texture_view_descriptor
            .as_ref()
            .and_then(|v| v.dimension)
            .map(|dim| format!("{dim:?}"));
        check(
            view.as_deref() == Some("Cube"),
            format!("{path}: view dimension {view:?}"),
        );
        let n = d.size.width as usize;
        let block = if format == "bc6h" { 4 } else { 1 };
        let texel_bytes = match format {
            "rgba32f" | "bc6h" => 16,
            "rgba16f" => 8,
            _ => 4,
        };
        let want: usize = (0..levels as usize)
            .map(|l| {
                let s = (n >> l).max(1).div_ceil(block);
                s * s * texel_bytes * 6
            })
            .sum();
        let len = image.data.as_ref().map_or(0, |b| b.len());
        check(
            len == want,
            format!("{path}: {len} bytes of texels (want {want})"),
        );
    }
    println!("bevy_image: {passed} passed, {failed} failed");
    if failed == 0 {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}
