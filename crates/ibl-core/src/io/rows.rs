//! What a streamed read delivers: rows of an equirect image, top to bottom (the readers of
//! `io` implement it; `crate::stream` resamples from it).

use crate::error::Result;
use std::path::Path;

/// Rows of an equirect image delivered top to bottom.
pub trait RowSource: Send {
    /// The file the rows come from (for errors and the memory budget).
    fn path(&self) -> &Path;
    /// Width in pixels.
    fn width(&self) -> usize;
    /// Height in rows.
    fn height(&self) -> usize;
    /// Channels per pixel (1 to 4, read as [`crate::image::Image::rgb`] reads them).
    fn channels(&self) -> usize;
    /// Appends the next `count` rows (row-major, channels interleaved) to `out`; `count` never
    /// runs past the last row. A source that cannot deliver them (a truncated or corrupt
    /// file) returns the error naming its file.
    fn read_rows(&mut self, count: usize, out: &mut Vec<f32>) -> Result<()>;
}
