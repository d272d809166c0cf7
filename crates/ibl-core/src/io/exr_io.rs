//! OpenEXR reading (any channel set of R, G, B, A or one grey channel; half, float or uint;
//! every compression the `exr` crate decodes, DWAB included) and writing (float uncompressed,
//! half in ZIP blocks).

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
) -> Result<exr::meta::OffsetTables> {
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
    Ok(tables)
}

/// The channels read, by index into the file's (name-sorted) list: R, G, B (and A) by role,
/// R and G for two-channel tables, else one grey channel (Y, or R, G, B, or the only one).
fn pick_channels<'a>(
    path: &Path,
    names: impl IntoIterator<Item = &'a exr::meta::attribute::Text>,
) -> Result<Vec<usize>> {
    let names: Vec<String> = names.into_iter().map(|n| n.to_string()).collect();
    let find = |r: &str| names.iter().position(|c| role(c) == r);
    let (ri, gi, bi, ai) = (find("R"), find("G"), find("B"), find("A"));
    Ok(match (ri, gi, bi) {
        (Some(r), Some(g), Some(b)) => {
            let mut v = vec![r, g, b];
            v.extend(ai);
            v
        }
        // Two-channel data (DFG-style tables) keeps both channels.
        (Some(r), Some(g), None) => vec![r, g],
        _ => {
            let grey = find("Y").or(ri).or(gi).or(bi);
            match grey.or(if names.len() == 1 { Some(0) } else { None }) {
                Some(c) => vec![c],
                None => {
                    return Err(Error::unsupported(
                        path,
                        format!("EXR channels {names:?}: need R,G,B(,A) or a single channel"),
                    ))
                }
            }
        }
    })
}

/// The one header of a file the block readers take: a single part of scan lines, flat (not
/// deep), every channel at full resolution; `None` for anything else.
fn flat_scan_lines(meta: &exr::meta::MetaData) -> Option<&exr::meta::header::Header> {
    let [header] = meta.headers.as_slice() else {
        return None;
    };
    let flat = !header.deep
        && matches!(header.blocks, exr::meta::BlockDescription::ScanLines)
        && header
            .channels
            .list
            .iter()
            .all(|c| c.sampling == exr::math::Vec2(1, 1));
    flat.then_some(header)
}

/// Where the picked channels sit in a decompressed scan-line block: each line holds every
/// channel's samples in turn (the file's name-sorted order), at its own sample size.
struct LineLayout {
    width: usize,
    /// Per picked channel: its byte offset in a block line, and its sample type.
    picked: Vec<(usize, exr::meta::attribute::SampleType)>,
    /// Bytes of one line of a block (every channel).
    line_bytes: usize,
}

impl LineLayout {
    /// The layout of `header`'s lines and the channels [`pick_channels`] reads from them.
    fn new(path: &Path, header: &exr::meta::header::Header) -> Result<Self> {
        let picked = pick_channels(path, header.channels.list.iter().map(|c| &c.name))?;
        let w = header.layer_size.0;
        let mut offsets = Vec::new();
        let mut at = 0;
        for c in &header.channels.list {
            offsets.push((at, c.sample_type));
            at += w * c.sample_type.bytes_per_sample();
        }
        Ok(LineLayout {
            width: w,
            picked: picked.iter().map(|&c| offsets[c]).collect(),
            line_bytes: at,
        })
    }

    /// `rows` lines of a decompressed block as interleaved f32 texels of the picked channels
    /// (native-endian samples, as [`interleave`] converts the crate's decode).
    fn convert(&self, block: &[u8], rows: usize, out: &mut [f32]) {
        use exr::meta::attribute::SampleType;
        let (w, ch) = (self.width, self.picked.len());
        for r in 0..rows {
            let line = &block[r * self.line_bytes..(r + 1) * self.line_bytes];
            let out = &mut out[r * w * ch..(r + 1) * w * ch];
            for (k, &(at, ty)) in self.picked.iter().enumerate() {
                let dst = out[k..].iter_mut().step_by(ch);
                match ty {
                    SampleType::F16 => {
                        dst.zip(line[at..at + 2 * w].chunks_exact(2))
                            .for_each(|(d, b)| {
                                *d = exr::prelude::f16::from_ne_bytes([b[0], b[1]]).to_f32()
                            })
                    }
                    SampleType::F32 => dst
                        .zip(line[at..at + 4 * w].chunks_exact(4))
                        .for_each(|(d, b)| *d = f32::from_ne_bytes([b[0], b[1], b[2], b[3]])),
                    SampleType::U32 => {
                        dst.zip(line[at..at + 4 * w].chunks_exact(4))
                            .for_each(|(d, b)| {
                                *d = u32::from_ne_bytes([b[0], b[1], b[2], b[3]]) as f32
                            })
                    }
                }
            }
        }
    }
}

/// A decompressed block's place: it must hold `rows` whole lines of the image's width
/// starting at line `y` (relative to the data window), or the file is damaged.
fn check_block(
    path: &Path,
    block: &exr::block::UncompressedBlock,
    layout: &LineLayout,
    y: usize,
    rows: usize,
) -> Result<()> {
    let (at, got) = (block.index.pixel_position.1, block.index.pixel_size.1);
    if at != y
        || got != rows
        || block.index.pixel_size.0 != layout.width
        || block.data.len() != rows * layout.line_bytes
    {
        return Err(Error::invalid(
            path,
            format!(
                "damaged EXR: a block of lines {at}..{} where lines {y}..{} were expected",
                at + got,
                y + rows
            ),
        ));
    }
    Ok(())
}

/// A scan-line EXR file's rows as f32, block by block in file order (each block read and
/// decompressed when its rows are asked for): the rows of a streamed resample, never the
/// file's bytes nor its image. Only for files whose blocks [`ExrRows::open`] has checked to
/// follow one another in increasing line order.
pub(crate) struct ExrRows {
    path: std::path::PathBuf,
    reader: std::io::BufReader<std::fs::File>,
    meta: exr::meta::MetaData,
    height: usize,
    layout: LineLayout,
    /// Lines per block (the last may hold fewer).
    block_lines: usize,
    /// Rows decoded from the current block and not yet delivered (interleaved f32).
    pending: Vec<f32>,
    /// The row the next block must start at.
    next_block_row: usize,
    /// The block buffers, held against the memory budget.
    _budget: super::budget::Reservation,
}

impl ExrRows {
    /// Opens `path` (`file_len` bytes) for a streamed read, with the checks of [`decode`]
    /// done first (a readable header, a size [`Image::check_size`] takes, every chunk in the
    /// file, whole, once, at its line): `Ok(None)` when the file is not one this reads (tiled,
    /// deep, several layers, subsampled channels, blocks not following one another in
    /// increasing line order): read it whole then.
    pub fn open(path: &Path, file_len: u64) -> Result<Option<Self>> {
        use std::io::{Read, Seek, SeekFrom};
        let bad =
            |e: exr::error::Error| Error::invalid(path, format!("not a readable EXR file: {e}"));
        let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
        let mut read = exr::io::PeekRead::new(std::io::BufReader::new(file));
        let meta = exr::meta::MetaData::read_from_buffered(&mut read, false).map_err(bad)?;
        let Some(header) = flat_scan_lines(&meta) else {
            return Ok(None);
        };
        let size = header.layer_size;
        Image::check_size(path, size.0 as u64, size.1 as u64)?;
        let layout = LineLayout::new(path, header)?;
        let count = header.chunk_count;
        if (count as u64).saturating_mul(8) > file_len {
            return Err(Error::invalid(
                path,
                format!(
                    "truncated EXR: {file_len} bytes cannot hold the offsets of the {count} chunks its header declares"
                ),
            ));
        }
        let tables =
            exr::meta::MetaData::read_offset_tables(&mut read, &meta.headers).map_err(bad)?;
        let table = &tables[0];
        // Every chunk whole, once, at its line (as [`check_chunks`]), read from the file at
        // its offset (4 + 4 bytes each), and each following the previous one.
        let lines = header.compression.scan_lines_per_block();
        let y0 = header.own_attributes.layer_position.1 as i64;
        let mut f = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
        let mut in_order = true;
        let mut prev_end: Option<u64> = None;
        let mut seen = std::collections::HashSet::with_capacity(count);
        for (k, &off) in table.iter().enumerate() {
            let missing = || {
                Error::invalid(
                    path,
                    format!(
                        "truncated or damaged EXR: chunk {k} of {} is missing (offset {off} of a {file_len}-byte file)",
                        table.len()
                    ),
                )
            };
            if off.checked_add(8).is_none_or(|e| e > file_len) || !seen.insert(off) {
                return Err(missing());
            }
            let mut b = [0u8; 8];
            f.seek(SeekFrom::Start(off))
                .map_err(|e| Error::io(path, e))?;
            f.read_exact(&mut b).map_err(|_| missing())?;
            let y = i32::from_le_bytes(b[..4].try_into().expect("4 bytes")) as i64;
            let len = i32::from_le_bytes(b[4..].try_into().expect("4 bytes")) as i64;
            let end = off as i64 + 8 + len;
            if len < 0 || end > file_len as i64 {
                return Err(missing());
            }
            if y != y0 + k as i64 * lines as i64 {
                return Err(Error::invalid(
                    path,
                    format!(
                        "damaged EXR: chunk {k} holds line {y}, expected {}",
                        y0 + k as i64 * lines as i64
                    ),
                ));
            }
            if prev_end.is_some_and(|e| e != off) {
                in_order = false;
            }
            prev_end = Some(end as u64);
        }
        if !in_order || table.is_empty() {
            return Ok(None);
        }
        let (w, h) = (size.0, size.1);
        // The block buffers: one block decompressed, its rows converted, and the compressed
        // chunk (at most as large as the block, or the crate refuses it).
        let block = (lines * layout.line_bytes) as u64;
        let _budget = super::budget::reserve(
            path,
            &format!("decoding {lines}-line blocks of a {w}x{h} EXR image"),
            block.saturating_mul(3) + (lines * w * layout.picked.len() * 4) as u64,
        )?;
        let mut file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
        file.seek(SeekFrom::Start(table[0]))
            .map_err(|e| Error::io(path, e))?;
        Ok(Some(ExrRows {
            path: path.to_path_buf(),
            reader: std::io::BufReader::with_capacity(1 << 20, file),
            meta,
            height: h,
            layout,
            block_lines: lines,
            pending: Vec::new(),
            next_block_row: 0,
            _budget,
        }))
    }

    /// Reads and decompresses the next block, appending its rows to `pending`.
    fn next_block(&mut self) -> Result<()> {
        let path = self.path.clone();
        let bad =
            |e: exr::error::Error| Error::invalid(&path, format!("not a readable EXR file: {e}"));
        let chunk = exr::block::chunk::Chunk::read(&mut self.reader, &self.meta).map_err(bad)?;
        // On this thread, under the guard: a decoder panic is an error naming the file.
        let meta = &self.meta;
        let block = super::guard(&path, "OpenEXR", || {
            exr::block::UncompressedBlock::decompress_chunk(chunk, meta, false).map_err(bad)
        })?;
        let y = self.next_block_row;
        let rows = self.block_lines.min(self.height.saturating_sub(y));
        check_block(&path, &block, &self.layout, y, rows)?;
        let stride = self.layout.width * self.layout.picked.len();
        let start = self.pending.len();
        self.pending.resize(start + rows * stride, 0.0);
        self.layout
            .convert(&block.data, rows, &mut self.pending[start..]);
        self.next_block_row = y + rows;
        Ok(())
    }
}

impl crate::io::rows::RowSource for ExrRows {
    fn path(&self) -> &Path {
        &self.path
    }
    fn width(&self) -> usize {
        self.layout.width
    }
    fn height(&self) -> usize {
        self.height
    }
    fn channels(&self) -> usize {
        self.layout.picked.len()
    }
    fn read_rows(&mut self, count: usize, out: &mut Vec<f32>) -> Result<()> {
        let stride = self.layout.width * self.layout.picked.len();
        while self.pending.len() < count * stride {
            self.next_block()?;
        }
        out.extend_from_slice(&self.pending[..count * stride]);
        self.pending.drain(..count * stride);
        Ok(())
    }
}

/// A single-part, flat, scan-line file (what HDRI libraries publish) decompressed block by
/// block on every core, each block straight into its rows of the image: `Ok(None)` for any
/// other file, which the crate's reader takes. [`check_chunks`] has checked the offset table
/// (every block whole, once, at its line); each block is checked again as it decompresses.
fn decode_blocks(
    path: &Path,
    bytes: &[u8],
    meta: &exr::meta::MetaData,
    tables: &exr::meta::OffsetTables,
) -> Result<Option<Image>> {
    use rayon::prelude::*;
    let (Some(header), [table]) = (flat_scan_lines(meta), tables.as_slice()) else {
        return Ok(None);
    };
    let (w, h) = (header.layer_size.0, header.layer_size.1);
    let lines = header.compression.scan_lines_per_block();
    if table.len() != h.div_ceil(lines) {
        return Ok(None);
    }
    let layout = LineLayout::new(path, header)?;
    let ch = layout.picked.len();
    let mut data = super::budget::try_zeroed::<f32>(path, w * h * ch)?;
    let bad = |e: exr::error::Error| Error::invalid(path, format!("not a readable EXR file: {e}"));
    // Each block under its own guard (a decoder panic on a pool thread is an error naming the
    // file); the first failure in line order is the one reported, whatever the thread count.
    let results: Vec<Result<()>> = data
        .par_chunks_mut(lines * w * ch)
        .zip(table.par_iter())
        .enumerate()
        .map(|(k, (out, &off))| {
            super::guard(path, "OpenEXR", || {
                let mut read = Cursor::new(bytes);
                read.set_position(off);
                let chunk = exr::block::chunk::Chunk::read(&mut read, meta).map_err(bad)?;
                let block = exr::block::UncompressedBlock::decompress_chunk(chunk, meta, false)
                    .map_err(bad)?;
                let rows = out.len() / (w * ch);
                check_block(path, &block, &layout, k * lines, rows)?;
                layout.convert(&block.data, rows, out);
                Ok(())
            })
        })
        .collect();
    results.into_iter().collect::<Result<()>>()?;
    Image::from_data(w, h, ch, data).map(Some)
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
    let tables = check_chunks(path, bytes, &meta, &mut cursor)?;
    // What decoding allocates at most (the crate's reader, below): its planes (every channel
    // at its sample size) and our interleaved f32 copy of at most four of them; the block
    // decode needs only the copy and a block a thread.
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

    match decode_blocks(path, bytes, &meta, &tables)? {
        Some(image) => Ok(image),
        None => decode_with_reader(path, bytes),
    }
}

/// Any other file the crate reads (tiled, multi-part, mip-mapped, subsampled), through its
/// own reader, the largest level of the first valid layer.
fn decode_with_reader(path: &Path, bytes: &[u8]) -> Result<Image> {
    let bad = |e: exr::error::Error| Error::invalid(path, format!("not a readable EXR file: {e}"));
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
    let picked = pick_channels(path, layer.channel_data.list.iter().map(|c| &c.name))?;
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
    // The header the crate's own writer makes for this image (the channels sorted by name);
    // the samples are left empty, the blocks are made below.
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
    let sample = match depth {
        FloatDepth::F32 => 4,
        FloatDepth::F16 => 2,
    };
    // The block of lines [y0, y0 + lines) as OpenEXR lays it out: line by line, each
    // channel's run of samples, little-endian.
    let block = |y0: usize, lines: usize, raw: &mut Vec<u8>| {
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
    };
    // ZIP where it pays: its first 16-line block is compressed, and the file is written
    // uncompressed (NO_COMPRESSION, a line a block, which every OpenEXR reader takes) when
    // that saved less than [`ZIP_MIN_SAVING`]. Radiance in f32 barely compresses (a chain of
    // 256² faces: 0.3–1.6% on the fixtures) and its deflate was 5% of a default bake's
    // instructions; halves and smooth tables (the LUTs) shrink by far more and keep ZIP.
    let mut raw = Vec::with_capacity(16 * w * order.len() * sample);
    let mut packed = Vec::new();
    block(0, Compression::ZIP16.scan_lines_per_block(), &mut raw);
    zip_block(&raw, &mut packed);
    let zip = (packed.len() as f64) < (1.0 - ZIP_MIN_SAVING) * raw.len() as f64;
    let encoding = if zip {
        Encoding::SMALL_LOSSLESS
    } else {
        Encoding::UNCOMPRESSED
    };
    let layer = Layer::new((w, h), LayerAttributes::default(), encoding, channels);
    let image = exr::image::Image::from_layer(layer);
    let headers = image.write().infer_meta_data();
    let lines = encoding.compression.scan_lines_per_block();
    let fail = |e: exr::error::Error| Error::invalid(path, format!("EXR encoding failed: {e}"));
    let mut out = Cursor::new(Vec::new());
    exr::block::write(&mut out, headers, true, |_, writer| {
        for (k, y0) in (0..h).step_by(lines).enumerate() {
            block(y0, lines, &mut raw);
            let data = if !zip {
                raw.clone()
            } else {
                // The first block is the probe's.
                if k > 0 {
                    zip_block(&raw, &mut packed);
                }
                if packed.len() < raw.len() {
                    std::mem::take(&mut packed)
                } else {
                    // OpenEXR stores a block that does not shrink as it is (readers compare
                    // the block's size with its uncompressed size).
                    raw.clone()
                }
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

/// Least share of its bytes ZIP must save on a file's first block for the file to be
/// compressed (see [`encode`]).
const ZIP_MIN_SAVING: f64 = 0.1;

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
    fn blocks_read_back_exactly_for_every_channel_count_depth_and_partial_block() {
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

    /// The parallel block decode against the crate's own whole-image reader, bit for bit:
    /// every compression the crate writes, a partial last block, mixed sample types and a
    /// channel that is not read; and the repository's real HDRIs.
    #[test]
    fn the_block_decode_equals_the_crates_reader() {
        use exr::image::{AnyChannel, AnyChannels, Encoding, Layer};
        use exr::meta::header::LayerAttributes;
        let (w, h) = (19usize, 37usize);
        let mut x = 0x853c_49e6_748f_ea9bu64;
        let mut next = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 40) as f32 * 1e-4
        };
        let half = |v: Vec<f32>| FlatSamples::F16(v.into_iter().map(f16::from_f32).collect());
        for compression in [
            Compression::Uncompressed,
            Compression::RLE,
            Compression::ZIP1,
            Compression::ZIP16,
            Compression::PIZ,
            Compression::PXR24,
            Compression::DWAA(None),
            Compression::DWAB(None),
        ] {
            let mut plane = || (0..w * h).map(|_| next()).collect::<Vec<f32>>();
            let channels = AnyChannels::sort(SmallVec::from_vec(vec![
                AnyChannel::new("R", half(plane())),
                AnyChannel::new("G", half(plane())),
                AnyChannel::new("B", half(plane())),
                AnyChannel::new("A", FlatSamples::F32(plane())),
                AnyChannel::new("Z", FlatSamples::U32((0..(w * h) as u32).collect())),
            ]));
            let encoding = Encoding {
                compression,
                blocks: exr::image::Blocks::ScanLines,
                line_order: LineOrder::Increasing,
            };
            let layer = Layer::new((w, h), LayerAttributes::default(), encoding, channels);
            let mut bytes = Vec::new();
            exr::image::Image::from_layer(layer)
                .write()
                .to_buffered(Cursor::new(&mut bytes))
                .unwrap();
            let path = Path::new("t.exr");
            let mut read = exr::io::PeekRead::new(Cursor::new(&bytes[..]));
            let meta = exr::meta::MetaData::read_from_buffered(&mut read, false).unwrap();
            let tables = check_chunks(path, &bytes, &meta, &mut read).unwrap();
            let blocks = decode_blocks(path, &bytes, &meta, &tables)
                .unwrap()
                .expect("a flat scan-line file takes the block decode");
            let whole = decode_with_reader(path, &bytes).unwrap();
            assert_eq!((blocks.width, blocks.height, blocks.channels), (w, h, 4));
            let bits = |i: &Image| i.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&blocks), bits(&whole), "{compression:?}");
        }
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/hdri");
        let mut real = 0;
        for e in std::fs::read_dir(dir).unwrap().flatten() {
            let path = e.path();
            if path.extension().is_some_and(|x| x == "exr") {
                let bytes = std::fs::read(&path).unwrap();
                let mut read = exr::io::PeekRead::new(Cursor::new(&bytes[..]));
                let meta = exr::meta::MetaData::read_from_buffered(&mut read, false).unwrap();
                let tables = check_chunks(&path, &bytes, &meta, &mut read).unwrap();
                // The block decode itself, not `decode`'s fallback compared with itself.
                let a = decode_blocks(&path, &bytes, &meta, &tables)
                    .unwrap()
                    .expect("the fixtures are flat scan-line files");
                let b = decode_with_reader(&path, &bytes).unwrap();
                assert_eq!(a, b, "{}", path.display());
                real += 1;
            }
        }
        assert!(real >= 3, "the repository's HDRIs");
    }

    /// A damaged block in the middle of a file the block decode takes is an error naming the
    /// file, whichever pool thread met it, never a panic nor an image with a hole. (Noise is
    /// stored raw, and EXR has no checksum: a smooth image, so that every block is deflated.)
    #[test]
    fn a_damaged_block_is_an_error_naming_the_file() {
        let (w, h, channels) = (64, 96, 3);
        let data: Vec<f32> = (0..w * h * channels)
            .map(|k| 1.0 + ((k / channels) % w) as f32 / w as f32)
            .collect();
        let img = Image::from_data(w, h, channels, data).unwrap();
        let bytes = encode(Path::new("t.exr"), &img, FloatDepth::F16).unwrap();
        let path = Path::new("t.exr");
        let mut read = exr::io::PeekRead::new(Cursor::new(&bytes[..]));
        let meta = exr::meta::MetaData::read_from_buffered(&mut read, false).unwrap();
        assert_eq!(meta.headers[0].compression, Compression::ZIP16);
        let tables = check_chunks(path, &bytes, &meta, &mut read).unwrap();
        assert!(decode_blocks(path, &bytes, &meta, &tables)
            .unwrap()
            .is_some());
        let mut bad = bytes.clone();
        let at = tables[0][tables[0].len() / 2] as usize + 8;
        bad[at..at + 16].fill(0xff);
        let err = decode(path, &bad).unwrap_err().to_string();
        assert!(err.contains("t.exr") && err.contains("EXR"), "{err}");
    }

    /// ZIP is kept where it pays: a smooth table (as the LUTs are) is stored in ZIP blocks and
    /// comes out much smaller than its samples; f32 noise (as radiance mostly is, to deflate)
    /// is stored uncompressed; both read back exactly (the exr crate, independent of the
    /// writer here) and both headers say what their blocks are.
    #[test]
    fn zip_is_kept_only_where_its_first_block_shrinks() {
        let (w, h, channels) = (64, 40, 3);
        let smooth: Vec<f32> = (0..w * h * channels)
            .map(|k| ((k / channels) % w) as f32 / w as f32 + 0.25 * (k % channels) as f32)
            .collect();
        let mut x = 0x9e37_79b9_7f4a_7c15u64;
        let noise: Vec<f32> = (0..w * h * channels)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                f32::from_bits(0x3f80_0000 | (x >> 41) as u32)
            })
            .collect();
        for (data, want, smaller) in [
            (smooth, Compression::ZIP16, true),
            (noise, Compression::Uncompressed, false),
        ] {
            let img = Image::from_data(w, h, channels, data).unwrap();
            let bytes = encode(Path::new("t.exr"), &img, FloatDepth::F32).unwrap();
            let meta = exr::meta::MetaData::read_from_buffered(Cursor::new(&bytes), true).unwrap();
            assert_eq!(meta.headers[0].compression, want);
            assert_eq!(
                bytes.len() < w * h * channels * 4 * 3 / 4,
                smaller,
                "{want:?}"
            );
            assert_eq!(decode(Path::new("t.exr"), &bytes).unwrap(), img);
        }
    }
}
