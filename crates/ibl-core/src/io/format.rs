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

/// Format codes of one pixel format in each container.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Codes {
    /// KTX2 `vkFormat` (VkFormat enum).
    pub vk: u32,
    /// KTX2 `typeSize`: the size of the format's data type (1 for block-compressed formats).
    pub ktx2_type_size: u32,
    /// DDS DX10 header `dxgiFormat` (DXGI_FORMAT enum).
    pub dxgi: u32,
    /// KTX1 `glType` (0 for compressed formats).
    pub gl_type: u32,
    /// KTX1 `glTypeSize`.
    pub gl_type_size: u32,
    /// KTX1 `glFormat` (0 for compressed formats).
    pub gl_format: u32,
    /// KTX1 `glInternalFormat`.
    pub gl_internal_format: u32,
    /// KTX1 `glBaseInternalFormat`.
    pub gl_base_internal_format: u32,
}

// OpenGL enums (Khronos gl.h / glext.h).
const GL_HALF_FLOAT: u32 = 0x140B;
const GL_FLOAT: u32 = 0x1406;
const GL_RGB: u32 = 0x1907;
const GL_RGBA: u32 = 0x1908;
const GL_RGBA32F: u32 = 0x8814;
const GL_RGBA16F: u32 = 0x881A;
const GL_R11F_G11F_B10F: u32 = 0x8C3A;
const GL_UNSIGNED_INT_10F_11F_11F_REV: u32 = 0x8C3B;
const GL_RGB9_E5: u32 = 0x8C3D;
const GL_UNSIGNED_INT_5_9_9_9_REV: u32 = 0x8C3E;
const GL_COMPRESSED_RGB_BPTC_UNSIGNED_FLOAT: u32 = 0x8E8F;

impl PixelFormat {
    /// The format's codes in KTX2 (vkFormat), DDS (DXGI) and KTX1 (OpenGL).
    pub fn codes(self) -> Codes {
        let (vk, ktx2_type_size, dxgi) = match self {
            PixelFormat::Rgba32f => (109, 4, 2),
            PixelFormat::Rgba16f => (97, 2, 10),
            PixelFormat::Rgb9e5 => (123, 4, 67),
            PixelFormat::B10g11r11 => (122, 4, 26),
            PixelFormat::Bc6h => (143, 1, 95),
        };
        let (gl_type, gl_type_size, gl_format, gl_internal_format, gl_base_internal_format) =
            match self {
                PixelFormat::Rgba32f => (GL_FLOAT, 4, GL_RGBA, GL_RGBA32F, GL_RGBA),
                PixelFormat::Rgba16f => (GL_HALF_FLOAT, 2, GL_RGBA, GL_RGBA16F, GL_RGBA),
                PixelFormat::Rgb9e5 => (GL_UNSIGNED_INT_5_9_9_9_REV, 4, GL_RGB, GL_RGB9_E5, GL_RGB),
                PixelFormat::B10g11r11 => (
                    GL_UNSIGNED_INT_10F_11F_11F_REV,
                    4,
                    GL_RGB,
                    GL_R11F_G11F_B10F,
                    GL_RGB,
                ),
                PixelFormat::Bc6h => (0, 1, 0, GL_COMPRESSED_RGB_BPTC_UNSIGNED_FLOAT, GL_RGB),
            };
        Codes {
            vk,
            ktx2_type_size,
            dxgi,
            gl_type,
            gl_type_size,
            gl_format,
            gl_internal_format,
            gl_base_internal_format,
        }
    }

    /// The format whose KTX2 vkFormat is `vk`.
    pub(crate) fn from_vk(vk: u32) -> Option<Self> {
        Self::ALL.into_iter().find(|f| f.codes().vk == vk)
    }

    /// The format whose DDS dxgiFormat is `dxgi`.
    pub(crate) fn from_dxgi(dxgi: u32) -> Option<Self> {
        Self::ALL.into_iter().find(|f| f.codes().dxgi == dxgi)
    }

    /// The format whose KTX1 glInternalFormat is `internal`.
    pub(crate) fn from_gl_internal(internal: u32) -> Option<Self> {
        Self::ALL
            .into_iter()
            .find(|f| f.codes().gl_internal_format == internal)
    }

    /// Texels along each side of a block (4 for BC6H, 1 for the others).
    pub(crate) fn block_dim(self) -> usize {
        if self == PixelFormat::Bc6h {
            4
        } else {
            1
        }
    }

    /// Bytes of one block (of one texel for the uncompressed formats).
    pub(crate) fn block_bytes(self) -> usize {
        match self {
            PixelFormat::Rgba32f | PixelFormat::Bc6h => 16,
            PixelFormat::Rgba16f => 8,
            PixelFormat::Rgb9e5 | PixelFormat::B10g11r11 => 4,
        }
    }

    /// Bytes of a `width`×`height` image: whole blocks, so a 1×1 BC6H level is one block.
    pub(crate) fn image_bytes(self, width: usize, height: usize) -> usize {
        let b = self.block_dim();
        width.div_ceil(b) * height.div_ceil(b) * self.block_bytes()
    }

    /// Largest value a channel can hold; larger ones are clamped to it when encoding (the
    /// blue channel of B10G11R11 holds up to 64512, see [`super::packed::UF10_MAX`]).
    pub fn max_value(self) -> f32 {
        match self {
            PixelFormat::Rgba32f => f32::MAX,
            PixelFormat::Rgba16f | PixelFormat::Bc6h => 65504.0,
            PixelFormat::Rgb9e5 => super::packed::RGB9E5_MAX,
            PixelFormat::B10g11r11 => super::packed::UF11_MAX,
        }
    }

    /// Whether decoding gives back exactly what was encoded.
    pub fn is_lossless(self) -> bool {
        self == PixelFormat::Rgba32f
    }
}
