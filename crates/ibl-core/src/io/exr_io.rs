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
    use exr::block::writer::ChunksWriter;
    let names = match img.channels {
        1 => vec!["Y"],
        2 => vec!["R", "G"],
        3 => vec!["R", "G", "B"],
        _ => vec!["R", "G", "B", "A"],
    };
    let (w, h) = (img.width, img.height);
    // The header the crate's own writer makes for this image (ZIP, 16-line blocks, the
    // channels sorted by name); the samples are left empty, the blocks are made below.
    let list: SmallVec<[AnyChannel<FlatSamples>; 4]> = names
        .iter()
        .map(|name| {
            let samples = match depth {
                FloatDepth::F32 => FlatSamples::F32(Vec::new()),
                FloatDepth::F16 => FlatSamples::F16(Vec::new()),
            };
            AnyChannel::new(*name, samples)
        })
        .collect();
    let channels = AnyChannels::sort(list);
    // Source channel of each file channel (the file's are in name order).
    let order: Vec<usize> = channels
        .list
        .iter()
        .map(|c| {
            let n = c.name.to_string();
            names.iter().position(|m| *m == n).expect("named above")
        })
        .collect();
    let layer = Layer::new(
        (w, h),
        LayerAttributes::default(),
        Encoding::SMALL_LOSSLESS,
        channels,
    );
    let image = exr::image::Image::from_layer(layer);
    let headers = image.write().infer_meta_data();
    let lines = Compression::ZIP16.scan_lines_per_block();
    let sample = match depth {
        FloatDepth::F32 => 4,
        FloatDepth::F16 => 2,
    };
    let fail = |e: exr::error::Error| Error::invalid(path, format!("EXR encoding failed: {e}"));
    let mut out = Cursor::new(Vec::new());
    exr::block::write(&mut out, headers, true, |_, writer| {
        let mut raw = Vec::with_capacity(lines * w * order.len() * sample);
        let mut packed = Vec::new();
        for (k, y0) in (0..h).step_by(lines).enumerate() {
            // The block as OpenEXR lays it out: line by line, each channel's run of samples,
            // little-endian.
            raw.clear();
            for y in y0..(y0 + lines).min(h) {
                let row = &img.data[y * w * img.channels..(y + 1) * w * img.channels];
                for &c in &order {
                    let values = row.iter().skip(c).step_by(img.channels);
                    match depth {
                        FloatDepth::F32 => values.for_each(|v| raw.extend(v.to_le_bytes())),
                        FloatDepth::F16 => {
                            values.for_each(|v| raw.extend(super::f16_saturating(*v).to_le_bytes()))
                        }
                    }
                }
            }
            zip_block(&raw, &mut packed);
            let data = if packed.len() < raw.len() {
                std::mem::take(&mut packed)
            } else {
                // OpenEXR stores a block that does not shrink as it is (readers compare the
                // block's size with its uncompressed size).
                raw.clone()
            };
            writer.write_chunk(
                k,
                exr::block::chunk::Chunk {
                    layer_index: 0,
                    compressed_block: exr::block::chunk::CompressedBlock::ScanLine(
                        exr::block::chunk::CompressedScanLineBlock {
                            y_coordinate: y0 as i32,
                            compressed_pixels_le: data,
                        },
                    ),
                },
            )?;
        }
        Ok(())
    })
    .map_err(fail)?;
    Ok(out.into_inner())
}

/// Deflate level of the ZIP blocks. Radiance in f32 barely compresses (the bytes of a
/// 256² × 5-level chain shrink by 2.6% at any level, measured 1 to 6), so the fastest level
/// gives the same files as the crate's level 4 in about two thirds of the time.
const ZIP_LEVEL: u8 = 1;

/// OpenEXR's ZIP compression of one block (ImfZip.cpp): the bytes split into even and odd
/// halves, each byte replaced by its difference to the previous one (+128), then zlib.
fn zip_block(raw: &[u8], out: &mut Vec<u8>) {
    let half = raw.len().div_ceil(2);
    let mut t = vec![0u8; raw.len()];
    for (k, &b) in raw.iter().enumerate() {
        t[if k % 2 == 0 { k / 2 } else { half + k / 2 }] = b;
    }
    let mut prev = t.first().copied().unwrap_or(0);
    for b in t.iter_mut().skip(1) {
        let cur = *b;
        *b = cur.wrapping_sub(prev).wrapping_add(128);
        prev = cur;
    }
    *out = miniz_oxide::deflate::compress_to_vec_zlib(&t, ZIP_LEVEL);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zip_blocks_read_back_exactly_for_every_channel_count_depth_and_partial_block() {
        // Heights that end on a partial 16-line block, widths that are odd, 1 to 4 channels,
        // f32 and f16, blocks that compress (flat areas) and blocks stored as they are
        // (noise): the decoder (the exr crate, independent of the block writer here) gives
        // back the same values.
        let mut x = 0x2545_f491_4f6c_dd1du64;
        for (w, h) in [(1, 1), (7, 16), (33, 17), (64, 50)] {
            for channels in 1..=4 {
                for depth in [FloatDepth::F32, FloatDepth::F16] {
                    let data: Vec<f32> = (0..w * h * channels)
                        .map(|k| {
                            x ^= x << 13;
                            x ^= x >> 7;
                            x ^= x << 17;
                            if (k / (w * channels)) % 3 == 0 {
                                1.5
                            } else {
                                (x >> 40) as f32 * 1e-3
                            }
                        })
                        .collect();
                    let img = Image::from_data(w, h, channels, data).unwrap();
                    let bytes = encode(Path::new("t.exr"), &img, depth).unwrap();
                    let back = decode(Path::new("t.exr"), &bytes).unwrap();
                    let want = match depth {
                        FloatDepth::F32 => img.clone(),
                        FloatDepth::F16 => Image {
                            data: img
                                .data
                                .iter()
                                .map(|&v| super::super::f16_saturating(v).to_f32())
                                .collect(),
                            ..img.clone()
                        },
                    };
                    assert_eq!(back, want, "{w}x{h}x{channels} {depth:?}");
                }
            }
        }
    }
}
