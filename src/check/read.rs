//! The one file read of the library: the text of a constraint file, size-limited and
//! checked as UTF-8. [`Checked::load`](super::Checked::load) uses it for the file a user's
//! test names, and `main.rs` for every command. Kept apart so the boundary "only `main.rs`
//! touches files" has exactly one documented exception.

use super::CheckError;
use crate::model::file::MAX_FILE_BYTES;
use std::path::Path;

/// Reads `path` as UTF-8 text of at most [`MAX_FILE_BYTES`].
pub fn read_text(path: &Path) -> Result<String, CheckError> {
    let fail = |message: String| CheckError::Read { path: path.display().to_string(), message };
    let bytes = std::fs::read(path).map_err(|e| fail(e.to_string()))?;
    if bytes.len() > MAX_FILE_BYTES {
        return Err(fail(format!("the file is too large ({} bytes; the limit is {MAX_FILE_BYTES})", bytes.len())));
    }
    String::from_utf8(bytes)
        .map_err(|e| fail(format!("not valid UTF-8 (invalid byte at offset {})", e.utf8_error().valid_up_to())))
}
