//! Pixel formats of GPU cube containers (KTX2, DDS, KTX1): what each stores per texel or
//! block, and the format codes each container uses for it.

/// How the texels of a cube or chain are stored in a container.
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
pub enum PixelFormat {
    /// 32-bit float RGBA (16 bytes a texel): exact.
    #[default]
    Rgba32f,
    /// 16-bit float RGBA (8 bytes a texel), saturating at ±65504.
    Rgba16f,
    /// Shared-exponent RGB9_E5 (4 bytes a texel), EXT_texture_shared_exponent rounding.
    Rgb9e5,
    /// Packed unsigned floats B10G11R11 (4 bytes a texel), round to nearest.
    B10g11r11,
    /// BC6H unsigned-float blocks (16 bytes per 4×4 block, 1 byte a texel).
    Bc6h,
}

impl PixelFormat {
    /// Every format, in the order help texts list them.
    pub const ALL: [PixelFormat; 5] = [
        PixelFormat::Rgba32f,
        PixelFormat::Rgba16f,
        PixelFormat::Rgb9e5,
        PixelFormat::B10g11r11,
        PixelFormat::Bc6h,
    ];

    /// The name flags and RON keys use.
    pub fn name(self) -> &'static str {
        match self {
            PixelFormat::Rgba32f => "rgba32f",
            PixelFormat::Rgba16f => "rgba16f",
            PixelFormat::Rgb9e5 => "rgb9e5",
            PixelFormat::B10g11r11 => "b10g11r11",
            PixelFormat::Bc6h => "bc6h",
        }
    }
}

/// BC6H encoder effort (the ISPC texture compressor's profiles).
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
pub enum Bc6hQuality {
    /// Fastest profile.
    Fast,
    /// Balanced profile.
    #[default]
    Basic,
    /// Slowest, most accurate profile.
    Slow,
}
