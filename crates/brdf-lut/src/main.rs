//! `brdf-lut`: the command line of the [`ibl_lut`] table bakes, one subcommand each.

fn main() {
    ibl_cli::main_subcommands(
        "brdf-lut",
        "BRDF lookup tables: split-sum DFG, Ashikhmin-Shirley size/bias, Fresnel tail",
        "BRDF lookup tables at texel centres (docs/CONVENTIONS.md): the split-sum DFG table, the \
         Ashikhmin-Shirley size/bias table, and the Fresnel-tail table of the SH-exponential \
         probes. The output format follows the extension: .exr (float), .png (16-bit), .json/.ron.",
        &[
            &ibl_lut::DFG,
            &ibl_lut::AS_SIZE_BIAS,
            &ibl_lut::FRESNEL_TAIL,
        ],
    )
}
