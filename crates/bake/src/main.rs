//! `bake`: plans, runs and cleans RON bake pipelines; the command line lives in the runner's
//! library (`ibl_pipeline::cli`), like every other binary's in its own.

fn main() {
    ibl_pipeline::cli::main()
}
