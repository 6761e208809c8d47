//! The one file read of the library: the text of a constraint file, size-limited and
//! checked as UTF-8. [`Checked::load`](super::Checked::load) uses it for the file a user's
//! test names, and `main.rs` for every command. Kept apart so the boundary "only `main.rs`
//! touches files" has exactly one documented exception.
//!
//! The size is bounded before or while reading, not after: a regular file past the limit is
//! refused by its length, unread, and of anything else at most one byte past the limit is
//! read, so `/dev/zero`, a pipe that never ends or a file of gigabytes is refused at once.
//!
//! Not here: what the text means (`model`), writing files (`main.rs`).

use super::CheckError;
use crate::model::file::MAX_FILE_BYTES;
use std::io::Read;
use std::path::Path;

/// Reads `path` as UTF-8 text of at most [`MAX_FILE_BYTES`].
pub fn read_text(path: &Path) -> Result<String, CheckError> {
    let fail = |message: String| CheckError::Read { path: path.display().to_string(), message };
    let too_large = || fail(format!("the file is too large (more than {MAX_FILE_BYTES} bytes, the limit)"));
    let file = std::fs::File::open(path).map_err(|e| fail(e.to_string()))?;
    // A regular file says its length: one past the limit is refused unread (a 3 GB file at
    // once, not after reading the limit's 64 MiB).
    if file.metadata().is_ok_and(|m| m.is_file() && m.len() > MAX_FILE_BYTES as u64) {
        return Err(too_large());
    }
    let mut bytes = Vec::new();
    // One byte more than the limit tells "too large" from "exactly at the limit" (for what
    // has no length: a device, a pipe).
    file.take(MAX_FILE_BYTES as u64 + 1).read_to_end(&mut bytes).map_err(|e| fail(e.to_string()))?;
    if bytes.len() > MAX_FILE_BYTES {
        return Err(too_large());
    }
    String::from_utf8(bytes)
        .map_err(|e| fail(format!("not valid UTF-8 (invalid byte at offset {})", e.utf8_error().valid_up_to())))
}
