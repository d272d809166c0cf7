//! Accuracy of every preset against the brute-force reference (the exact kernel summed over
//! every source texel) on the small fixtures, at every level: `default` within 1% and `high`
//! within 0.3% mean absolute relative error of luminance.

use ibl_core::envmap::load_environment;
use ibl_core::progress::NoProgress;
use ibl_prefilter::bake::{bake_chain, ErrorStats, Params, Quality};
use std::path::PathBuf;

fn fixture(name: &str) -> PathBuf {
    ibl_testkit::fixture(&format!("hdri/{name}"))
}

const FIXTURES: [&str; 4] = [
    "studio_256.exr",
    "sunset_256.exr",
    "interior_256.exr",
    "city_512.exr",
];

/// Per fixture and chain shape: the reference chain, then each preset's error per level.
#[test]
fn presets_meet_their_error_bounds_at_every_level() {
    let mut worst = [0.0f64; 3];
    for name in FIXTURES {
        let env = load_environment(&fixture(name), false).unwrap().env;
        for (size, levels) in [(32usize, 5usize), (32, 3)] {
            let base = Params {
                size,
                levels: Some(levels),
                // The filter's accuracy: levels exact (the lookup fit moves them on purpose).
                fit_lookup: Some(false),
                ..Default::default()
            };
            let reference = bake_chain(
                &Params {
                    reference: true,
                    ..base.clone()
                },
                &env,
                &NoProgress,
            )
            .unwrap();
            for (qi, q) in [Quality::Draft, Quality::Default, Quality::High]
                .into_iter()
                .enumerate()
            {
                let chain = bake_chain(
                    &Params {
                        quality: q,
                        ..base.clone()
                    },
                    &env,
                    &NoProgress,
                )
                .unwrap();
                let mut line = format!(
                    "{name} size {size} levels {levels} source {} {:>7}:",
                    chain.report.source_size,
                    q.name()
                );
                for l in 1..levels {
                    let e = ErrorStats::between(&chain.mips.levels[l], &reference.mips.levels[l]);
                    line += &format!(
                        "  r={:.2} mare {:.4}% rms {:.4}%",
                        chain.report.level[l].roughness,
                        100.0 * e.mean_abs_rel,
                        100.0 * e.rms_rel
                    );
                    worst[qi] = worst[qi].max(e.mean_abs_rel);
                }
                eprintln!("{line}");
            }
        }
    }
    eprintln!(
        "worst mean abs relative error: draft {:.4}%, default {:.4}%, high {:.4}%",
        100.0 * worst[0],
        100.0 * worst[1],
        100.0 * worst[2]
    );
    assert!(worst[1] < 0.01, "default: {}", worst[1]);
    assert!(worst[2] < 0.003, "high: {}", worst[2]);
}
