//! What the material bakes share about their output file: the format checks of `--bits` and
//! `--half`, the encoder options, and refusing to write over an input.

use ibl_core::io::{self, FloatDepth, WriteOptions};
use ibl_core::Error;
use std::path::{Path, PathBuf};

/// Checks `--bits` / `--half` against the output's format (.png or .exr); `what` names the
/// map in the message ("quaternion maps", "TPR maps").
pub fn validate(out: &Path, bits: u8, half: bool, what: &str) -> ibl_core::Result<()> {
    match io::extension(out).as_str() {
        "png" if half => Err(Error::param(
            "--half applies to EXR outputs; this one is a PNG",
        )),
        "exr" if bits != 16 => Err(Error::param(
            "--bits applies to PNG outputs; this one is an EXR (see --half)",
        )),
        "png" | "exr" => Ok(()),
        other => Err(Error::unsupported(
            out,
            format!("{what} are written as .png or .exr, not '.{other}'"),
        )),
    }
}

/// Encoder options of a data map: linear, no tone mapping; `bits` for PNG, `half` for EXR.
pub(crate) fn write_options(bits: u8, half: bool) -> WriteOptions {
    WriteOptions {
        float: if half {
            FloatDepth::F16
        } else {
            FloatDepth::F32
        },
        png_bits: bits,
        png_tonemap: false,
        png_srgb: false,
    }
}

/// `path` made absolute with symbolic links and `..` resolved: the file itself when it
/// exists, else its (existing) folder joined with its name. None when neither resolves.
fn resolved(path: &Path) -> Option<PathBuf> {
    if let Ok(p) = path.canonicalize() {
        return Some(p);
    }
    let name = path.file_name()?;
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    Some(parent.canonicalize().ok()?.join(name))
}

/// Whether `a` and `b` name the same file (however spelt; hard links too on Unix).
pub fn same_file(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let (Ok(x), Ok(y)) = (std::fs::metadata(a), std::fs::metadata(b)) {
            if (x.dev(), x.ino()) == (y.dev(), y.ino()) {
                return true;
            }
        }
    }
    match (resolved(a), resolved(b)) {
        (Some(x), Some(y)) => x == y,
        _ => a == b,
    }
}

/// Refuses an output that is one of the inputs (writing it would destroy the input).
pub(crate) fn refuse_overwriting_input<'a>(
    out: &Path,
    inputs: impl IntoIterator<Item = &'a Path>,
) -> ibl_core::Result<()> {
    for input in inputs {
        if same_file(out, input) {
            return Err(Error::invalid(
                out,
                format!(
                    "the output is the input {} (it would be overwritten): write elsewhere",
                    input.display()
                ),
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_file_however_spelt() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        std::fs::create_dir(d.join("sub")).unwrap();
        std::fs::write(d.join("a.png"), b"x").unwrap();
        assert!(same_file(&d.join("a.png"), &d.join("sub/../a.png")));
        assert!(same_file(&d.join("a.png"), &d.join("./a.png")));
        assert!(!same_file(&d.join("a.png"), &d.join("b.png")));
        assert!(!same_file(&d.join("a.png"), &d.join("sub/a.png")));
        // Neither exists: compared by folder and name.
        assert!(same_file(&d.join("n.png"), &d.join("sub/../n.png")));
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink(d.join("a.png"), d.join("link.png")).unwrap();
            assert!(same_file(&d.join("a.png"), &d.join("link.png")));
            std::fs::hard_link(d.join("a.png"), d.join("hard.png")).unwrap();
            assert!(same_file(&d.join("a.png"), &d.join("hard.png")));
        }
        let e = refuse_overwriting_input(&d.join("sub/../a.png"), [d.join("a.png").as_path()])
            .err()
            .unwrap();
        assert!(e.to_string().contains("is the input"), "{e}");
        assert_eq!(e.class(), ibl_core::error::ErrorClass::InvalidInput);
        assert!(refuse_overwriting_input(&d.join("q.png"), [d.join("a.png").as_path()]).is_ok());
    }

    #[test]
    fn formats_are_checked_against_bits_and_half() {
        assert!(validate(Path::new("q.png"), 16, false, "maps").is_ok());
        assert!(validate(Path::new("q.png"), 8, false, "maps").is_ok());
        assert!(validate(Path::new("q.exr"), 16, true, "maps").is_ok());
        assert!(validate(Path::new("q.png"), 16, true, "maps").is_err());
        assert!(validate(Path::new("q.exr"), 8, false, "maps").is_err());
        let e = validate(Path::new("q.hdr"), 16, false, "TPR maps")
            .err()
            .unwrap();
        assert!(e
            .to_string()
            .contains("TPR maps are written as .png or .exr"));
        let o = write_options(8, true);
        assert_eq!((o.png_bits, o.float), (8, FloatDepth::F16));
        assert!(!o.png_tonemap && !o.png_srgb);
    }
}
