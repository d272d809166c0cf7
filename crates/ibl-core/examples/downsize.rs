//! Box-downsizes an image by an integer factor (used to make the small test fixtures):
//! `cargo run --example downsize -- IN OUT FACTOR [--half]`.

use ibl_core::image::Image;
use ibl_core::io::{self, ColorSpace, FloatDepth, WriteOptions};
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (src, dst, k) = (
        PathBuf::from(&args[0]),
        PathBuf::from(&args[1]),
        args[2].parse::<usize>()?,
    );
    let half = args.iter().any(|a| a == "--half");
    let linear = if io::extension(&dst) == "png" {
        ColorSpace::Linear
    } else {
        ColorSpace::Srgb
    };
    let img = io::read_image(&src, linear)?;
    let (w, h) = (img.width / k, img.height / k);
    let mut out = Image::new(w, h, img.channels);
    for y in 0..h {
        for x in 0..w {
            let mut acc = vec![0.0f64; img.channels];
            for b in 0..k {
                for a in 0..k {
                    for (c, v) in img.texel(x * k + a, y * k + b).iter().enumerate() {
                        acc[c] += *v as f64;
                    }
                }
            }
            for (c, v) in out.texel_mut(x, y).iter_mut().enumerate() {
                *v = (acc[c] / (k * k) as f64) as f32;
            }
        }
    }
    let opts = WriteOptions {
        float: if half {
            FloatDepth::F16
        } else {
            FloatDepth::F32
        },
        png_bits: 8,
        ..Default::default()
    };
    io::write_image(&dst, &out, &opts)?;
    Ok(())
}
