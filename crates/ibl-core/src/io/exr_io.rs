//! OpenEXR reading (any channel set of R, G, B, A or one grey channel; half, float or uint;
//! every compression the `exr` crate decodes, DWAB included) and writing (ZIP, float or half).

use super::FloatDepth;
use crate::error::{Error, Result};
use crate::image::Image;
use exr::prelude::*;
use std::io::Cursor;
use std::path::Path;

fn sample_count(samples: &FlatSamples) -> usize {
    match samples {
        FlatSamples::F16(v) => v.len(),
        FlatSamples::F32(v) => v.len(),
        FlatSamples::U32(v) => v.len(),
    }
}

/// Writes one channel into every `stride`-th value of `out` (interleaving in one pass, with
/// no per-channel copy: the decoded image already holds every sample once).
fn interleave(samples: &FlatSamples, out: &mut [f32], stride: usize) {
    let dst = out.iter_mut().step_by(stride);
    match samples {
        FlatSamples::F16(v) => dst.zip(v).for_each(|(d, h)| *d = h.to_f32()),
        FlatSamples::F32(v) => dst.zip(v).for_each(|(d, x)| *d = *x),
        FlatSamples::U32(v) => dst.zip(v).for_each(|(d, u)| *d = *u as f32),
    }
}

/// Channel role from its name: the part after the last '.', so `diffuse.R` is red.
fn role(name: &str) -> String {
    name.rsplit('.').next().unwrap_or(name).to_ascii_uppercase()
}

/// Checks the chunk offset tables before anything is decoded: every chunk the header's size
/// needs must be in the file, each once, whole: the decoder leaves the texels of a missing
/// chunk at zero (a truncated or damaged file would read as an image with black bands), and a
/// small file declaring a huge image cannot even hold the table of its chunks. Scan-line
/// chunks must also start at the line their index says (OpenEXR file layout, "Offset
/// Tables" and "Scan Line Chunks").
fn check_chunks<R: std::io::Read>(
    path: &Path,
    bytes: &[u8],
    meta: &exr::meta::MetaData,
    read: &mut exr::io::PeekRead<R>,
) -> Result<()> {
    let count: usize = meta.headers.iter().map(|h| h.chunk_count).sum();
    if (count as u64).saturating_mul(8) > bytes.len() as u64 {
        return Err(Error::invalid(
            path,
            format!(
                "truncated EXR: {} bytes cannot hold the offsets of the {count} chunks its header declares",
                bytes.len()
            ),
        ));
    }
    let tables = exr::meta::MetaData::read_offset_tables(read, &meta.headers)
        .map_err(|e| Error::invalid(path, format!("not a readable EXR file: {e}")))?;
    let multipart = meta.requirements.has_multiple_layers;
    let mut seen = std::collections::HashSet::with_capacity(count);
    let le_i32 = |at: usize| -> Option<i64> {
        bytes
            .get(at..at + 4)
            .map(|b| i32::from_le_bytes(b.try_into().expect("4 bytes")) as i64)
    };
    for (part, (header, table)) in meta.headers.iter().zip(&tables).enumerate() {
        let tiled = matches!(header.blocks, exr::meta::BlockDescription::Tiles(_));
        let lines = header.compression.scan_lines_per_block() as i64;
        let y0 = header.own_attributes.layer_position.1 as i64;
        for (k, &off) in table.iter().enumerate() {
            let missing = || {
                Error::invalid(
                    path,
                    format!(
                        "truncated or damaged EXR: chunk {k} of {} is missing (offset {off} of a {}-byte file)",
                        table.len(),
                        bytes.len()
                    ),
                )
            };
            let mut at = usize::try_from(off).map_err(|_| missing())?;
            if multipart {
                at = at.checked_add(4).ok_or_else(missing)?;
            }
            // Scan lines: y, then the data size; tiles: four coordinates, then the size.
            let head = if tiled { 16 } else { 4 };
            let len = le_i32(at + head).ok_or_else(missing)?;
            let end = (at + head + 4) as i64 + len;
            if len < 0 || end > bytes.len() as i64 || !seen.insert(off) {
                return Err(missing());
            }
            if !tiled && !multipart && part == 0 {
                let y = le_i32(at).ok_or_else(missing)?;
                if y != y0 + k as i64 * lines {
                    return Err(Error::invalid(
                        path,
                        format!(
                            "damaged EXR: chunk {k} holds line {y}, expected {}",
                            y0 + k as i64 * lines
                        ),
                    ));
                }
            }
        }
    }
    Ok(())
}

pub fn decode(path: &Path, bytes: &[u8]) -> Result<Image> {
    let bad = |e: exr::error::Error| Error::invalid(path, format!("not a readable EXR file: {e}"));
    // Header first: refuse absurd sizes before the decoder allocates.
    let mut cursor = exr::io::PeekRead::new(Cursor::new(bytes));
    let meta = exr::meta::MetaData::read_from_buffered(&mut cursor, false).map_err(bad)?;
    let header = meta
        .headers
        .first()
        .ok_or_else(|| Error::invalid(path, "EXR file has no layers"))?;
    if header.deep {
        return Err(Error::unsupported(path, "deep EXR data"));
    }
    let size = header.layer_size;
    Image::check_size(path, size.0 as u64, size.1 as u64)?;
    check_chunks(path, bytes, &meta, &mut cursor)?;
    // What decoding allocates: the crate's planes (every channel at its sample size) and our
    // interleaved f32 copy of at most four of them.
    let texels = size.0 as u64 * size.1 as u64;
    let plane_bytes: u64 = header
        .channels
        .list
        .iter()
        .map(|c| c.sample_type.bytes_per_sample() as u64)
        .sum();
    let _budget = super::budget::reserve(
        path,
        &format!("decoding a {}x{} EXR image", size.0, size.1),
        texels.saturating_mul(plane_bytes + 16),
    )?;

    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        // On this thread, so that a decoder panic unwinds to `io::guard` (a panic in the
        // crate's worker threads aborts the process).
        .non_parallel()
        .from_buffered(Cursor::new(bytes))
        .map_err(bad)?;
    let layer = image.layer_data;
    let (w, h) = (layer.size.0, layer.size.1);
    let find = |r: &str| {
        layer
            .channel_data
            .list
            .iter()
            .position(|c| role(&c.name.to_string()) == r)
    };
    let (ri, gi, bi, ai) = (find("R"), find("G"), find("B"), find("A"));
    let picked: Vec<usize> = match (ri, gi, bi) {
        (Some(r), Some(g), Some(b)) => {
            let mut v = vec![r, g, b];
            v.extend(ai);
            v
        }
        // Two-channel data (DFG-style tables) keeps both channels.
        (Some(r), Some(g), None) => vec![r, g],
        _ => {
            let grey = find("Y").or(ri).or(gi).or(bi);
            match grey.or(if layer.channel_data.list.len() == 1 {
                Some(0)
            } else {
                None
            }) {
                Some(c) => vec![c],
                None => {
                    let names: Vec<String> = layer
                        .channel_data
                        .list
                        .iter()
                        .map(|c| c.name.to_string())
                        .collect();
                    return Err(Error::unsupported(
                        path,
                        format!("EXR channels {names:?}: need R,G,B(,A) or a single channel"),
                    ));
                }
            }
        }
    };
    let n = w * h;
    let list = &layer.channel_data.list;
    if picked
        .iter()
        .any(|&c| sample_count(&list[c].sample_data) != n)
    {
        return Err(Error::invalid(
            path,
            "EXR channels are subsampled or truncated",
        ));
    }
    let channels = picked.len();
    let mut data = super::budget::try_zeroed::<f32>(path, n * channels)?;
    for (k, &c) in picked.iter().enumerate() {
        interleave(&list[c].sample_data, &mut data[k..], channels);
    }
    Image::from_data(w, h, channels, data)
}

pub fn encode(path: &Path, img: &Image, depth: FloatDepth) -> Result<Vec<u8>> {
    let names = match img.channels {
        1 => vec!["Y"],
        2 => vec!["R", "G"],
        3 => vec!["R", "G", "B"],
        _ => vec!["R", "G", "B", "A"],
    };
    let n = img.width * img.height;
    let list: SmallVec<[AnyChannel<FlatSamples>; 4]> = names
        .iter()
        .enumerate()
        .map(|(c, name)| {
            let plane = (0..n).map(|k| img.data[k * img.channels + c]);
            let samples = match depth {
                FloatDepth::F32 => FlatSamples::F32(plane.collect()),
                FloatDepth::F16 => FlatSamples::F16(plane.map(super::f16_saturating).collect()),
            };
            AnyChannel::new(*name, samples)
        })
        .collect();
    let layer = Layer::new(
        (img.width, img.height),
        LayerAttributes::default(),
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(list),
    );
    let image = exr::image::Image::from_layer(layer);
    let mut out = Cursor::new(Vec::new());
    image
        .write()
        // On this thread: callers encode many faces at once on the rayon pool already, and
        // the crate's parallel writer builds a thread pool per file.
        .non_parallel()
        .to_buffered(&mut out)
        .map_err(|e| Error::invalid(path, format!("EXR encoding failed: {e}")))?;
    Ok(out.into_inner())
}
