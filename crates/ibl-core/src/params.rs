//! One `Params` struct per bake derives both `clap::Args` and serde; this makes clap's
//! defaults the single source of defaults for the CLI, RON keys and `Default`.

/// The value of `P` when no flag is given: what `Default` and serde's `default` use.
/// Panics only if a `Params` field has no default, which its own unit test catches.
///
/// A flag the CLI requires (`hv-lut --nu`) has no default: it is `None` here, and the bake's
/// validation refuses it when a RON pipeline leaves it out.
pub fn clap_defaults<P: clap::Args + clap::FromArgMatches>() -> P {
    let cmd = P::augment_args(clap::Command::new("defaults").no_binary_name(true))
        .mut_args(|a| a.required(false));
    let m = cmd
        .try_get_matches_from(Vec::<String>::new())
        .expect("every Params field has a default");
    P::from_arg_matches(&m).expect("defaults parse")
}

/// The `--rotate` check every environment bake shares: a finite number of degrees.
pub fn check_rotate(degrees: f32) -> crate::Result<()> {
    if degrees.is_finite() {
        Ok(())
    } else {
        Err(crate::Error::param(
            "--rotate must be a finite number of degrees",
        ))
    }
}
