//! Why a bake failed.

use std::path::{Path, PathBuf};

/// Why a bake failed.
#[derive(Debug, thiserror::Error)]
pub enum BakeError {
    /// A setting of the scene is out of range; the message names it.
    #[error("{0}")]
    Setting(String),
    /// An input file (the scene file, a height field or its sidecar) cannot be used.
    #[error("{}: {msg}", path.display())]
    Input {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        msg: String,
    },
    /// An output file cannot be written.
    #[error("{path}: {msg}")]
    Output {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        msg: String,
    },
}

impl BakeError {
    /// An input error naming `path`.
    pub(crate) fn input(path: &Path, e: impl std::fmt::Display) -> BakeError {
        BakeError::Input {
            path: path.to_path_buf(),
            msg: e.to_string(),
        }
    }
}

/// An output error naming `path`.
pub(crate) fn out_err(path: &Path, e: impl std::fmt::Display) -> BakeError {
    BakeError::Output {
        path: path.to_path_buf(),
        msg: e.to_string(),
    }
}
