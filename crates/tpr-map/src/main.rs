//! `tpr-map`: the command line of the [`ibl_material::TPR_MAP`] bake.

fn main() {
    ibl_cli::main(&ibl_material::TPR_MAP)
}
