//! `irradiance`: the command line of the [`ibl_env::IRRADIANCE`] bake.

fn main() {
    ibl_cli::main(&ibl_env::IRRADIANCE)
}
