//! `equirect-to-cube`: the command line of the [`ibl_env::EQUIRECT_TO_CUBE`] bake.

fn main() {
    ibl_cli::main(&ibl_env::EQUIRECT_TO_CUBE)
}
