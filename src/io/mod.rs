//! Files: particle output (VTK) and checkpoints.

pub mod checkpoint;
pub mod vtk;

use crate::error::{Error, ErrorKind, Result};
use std::path::{Path, PathBuf};

/// Writes `bytes` to `path` through a temporary file in the same directory and a rename, so a
/// reader never sees a half-written file and an existing file is replaced only by a complete one.
pub(crate) fn write_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = PathBuf::from(tmp);
    if let Err(e) = std::fs::write(&tmp, bytes) {
        let _ = std::fs::remove_file(&tmp);
        return Err(io_error("writing", path, e));
    }
    if let Err(e) = std::fs::rename(&tmp, path) {
        let _ = std::fs::remove_file(&tmp);
        return Err(io_error("writing", path, e));
    }
    Ok(())
}

/// An I/O failure that names what was being done and the path (the operating system's message
/// alone, "No such file or directory", does not say which file).
pub(crate) fn io_error(doing: &str, path: &Path, e: std::io::Error) -> Error {
    Error::new(ErrorKind::Io, format!("{doing} {}: {e}", path.display()))
}
