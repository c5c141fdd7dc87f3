//! A slide's own levels copied as stored into an output that holds any downsample between
//! its levels (`--levels stored`: a pyramidal TIFF, a DICOM series), nothing decoded.

use crate::error::{Result, TilerError};
use crate::job::Progress;
use crate::sink::TileSink;
use crate::source::stored::{self, StoredLevels};

/// Whether a stored tile (its bytes, its level's tile size) is of the form the output declares.
pub(crate) type Fits<'a> = &'a dyn Fn(&[u8], (u32, u32)) -> bool;

/// Copies every tile of every level of `levels` into `sink` as that level's tile, row by row
/// (`--levels stored`: a TIFF's or a DICOM series' levels as the slide stores them); says how
/// many. Each tile must be what `fits` takes of its stored bytes and its level's tile size
/// (the form of its level's first tile, which the output declares for all, `form` naming it), else the run fails
/// naming the file, the level and the tile.
pub(crate) fn copy(
    sink: &dyn TileSink,
    levels: &StoredLevels,
    form: &str,
    fits: Fits,
    progress: &dyn Progress,
) -> Result<u64> {
    let mut copied = 0;
    for (k, level) in levels.levels.iter().enumerate() {
        let (w, h) = level.tiles.tile_size();
        let (across, down) = (level.width.div_ceil(w), level.height.div_ceil(h));
        for row in 0..down {
            if progress.cancelled() {
                return Err(TilerError::Interrupted);
            }
            for col in 0..across {
                let file = level.tiles.tile(col, row).map_err(|e| stored::in_level(e, k, level.page))?;
                let Some(file) = file.filter(|f| fits(f, (w, h))) else {
                    return Err(TilerError::decode(
                        &levels.path,
                        format!(
                            "level {k} (page {}): the tile at column {col}, row {row} is not a {w}x{h} {form} tile as the level's first is, so the level cannot be copied as stored; --levels pow2 makes the output from the decoded pixels",
                            level.page
                        ),
                    ));
                };
                sink.write_stored(k as u32, col, row, &file)?;
                copied += 1;
            }
            progress.advance(u64::from(across));
        }
    }
    Ok(copied)
}
