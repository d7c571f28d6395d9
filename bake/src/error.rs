//! Why a bake failed.

use std::path::{Path, PathBuf};

/// Why a bake failed.
#[derive(Debug, thiserror::Error)]
pub enum BakeError {
    /// The scene file, its height field or a setting cannot be used; the message names it.
    #[error("{0}")]
    Input(String),
    /// An output file cannot be written.
    #[error("{path}: {msg}")]
    Output {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        msg: String,
    },
}

/// An output error naming `path`.
pub(crate) fn out_err(path: &Path, e: impl std::fmt::Display) -> BakeError {
    BakeError::Output {
        path: path.to_path_buf(),
        msg: e.to_string(),
    }
}
