//! Schlick's Fresnel approximation (Schlick 1994; Kurt et al. 2010 eq. 12, Silvennoinen et al. 2025 eq. 4).

/// Schlick's weight (1 − cos θ)⁵, the "Fresnel tail" χ of Marcolongo 2020 §4.3.3 and Silvennoinen et al. 2025 eq. 7.
/// `cos_theta` is clamped to [0, 1].
#[inline]
pub fn schlick_weight(cos_theta: f32) -> f32 {
    let x = (1.0 - cos_theta).clamp(0.0, 1.0);
    let x2 = x * x;
    x2 * x2 * x
}

/// F = F0 + (1 − F0)(1 − cos θ)⁵ (Schlick 1994).
#[inline]
pub fn fresnel_schlick(f0: f32, cos_theta: f32) -> f32 {
    f0 + (1.0 - f0) * schlick_weight(cos_theta)
}

/// Schlick with an RGB F0.
#[inline]
pub fn fresnel_schlick_rgb(f0: [f32; 3], cos_theta: f32) -> [f32; 3] {
    let w = schlick_weight(cos_theta);
    f0.map(|f| f + (1.0 - f) * w)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn schlick_end_points_and_monotonicity() {
        assert_eq!(fresnel_schlick(0.04, 1.0), 0.04);
        assert_eq!(fresnel_schlick(0.04, 0.0), 1.0);
        assert_eq!(schlick_weight(-0.5), 1.0);
        assert_eq!(schlick_weight(1.5), 0.0);
        let mut last = 2.0;
        for k in 0..=100 {
            let f = fresnel_schlick(0.3, k as f32 / 100.0);
            assert!(f <= last);
            last = f;
        }
        // F0·(1−χ) + χ: the split the LUTs store.
        let c = 0.37;
        let w = schlick_weight(c);
        assert!((fresnel_schlick(0.5, c) - (0.5 * (1.0 - w) + w)).abs() < 1e-7);
        assert_eq!(fresnel_schlick_rgb([0.04, 0.5, 1.0], 1.0), [0.04, 0.5, 1.0]);
    }
}
