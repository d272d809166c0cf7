//! `shexp-fit`: the command line of the [`ibl_shexp::SHEXP_FIT`] bake.

fn main() {
    ibl_cli::main(&ibl_shexp::SHEXP_FIT)
}
