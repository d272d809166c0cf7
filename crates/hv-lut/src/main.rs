//! `hv-lut`: the command line of the [`ibl_lut::HV_LUT`] bake.

fn main() {
    ibl_cli::main(&ibl_lut::HV_LUT)
}
