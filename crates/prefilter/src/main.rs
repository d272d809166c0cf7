//! `prefilter`: the command line of the [`ibl_prefilter::PREFILTER`] bake.

fn main() {
    ibl_cli::main(&ibl_prefilter::PREFILTER)
}
