//! Errors of the safe API. Each carries a kind (mapped one to one onto a C status code) and a
//! message that names what was wrong.

use std::fmt;

/// What kind of failure happened. The C API maps each kind to a fixed `RkmpmStatus` number.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorKind {
    /// An argument is out of range, not finite, or inconsistent with the simulation.
    InvalidArgument,
    /// A call came at the wrong time (for example changing the shape function after stepping).
    InvalidState,
    /// A material id that was never added.
    UnknownMaterial,
    /// A particle lies (or would move) outside the grid's domain.
    OutsideGrid,
    /// The time step is above the stable limit.
    UnstableTimeStep,
    /// A step produced NaN or infinity.
    NonFinite,
    /// A step produced an inverted particle (det F <= 0).
    InvertedParticle,
    /// The body-force callback reported a failure.
    Callback,
    /// Reading or writing a file failed.
    Io,
    /// The feature is not available in this build.
    Unsupported,
    /// A checkpoint file is truncated, damaged or not a checkpoint.
    CorruptFile,
    /// Storage (for example the grid's nodes) could not be allocated.
    OutOfMemory,
}

/// An error with its kind and a human-readable message.
#[derive(Debug, Clone, PartialEq)]
pub struct Error {
    pub kind: ErrorKind,
    pub message: String,
}

impl Error {
    pub fn new(kind: ErrorKind, message: impl Into<String>) -> Self {
        Error {
            kind,
            message: message.into(),
        }
    }
    pub fn invalid(message: impl Into<String>) -> Self {
        Self::new(ErrorKind::InvalidArgument, message)
    }
    pub fn state(message: impl Into<String>) -> Self {
        Self::new(ErrorKind::InvalidState, message)
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:?}: {}", self.kind, self.message)
    }
}

impl std::error::Error for Error {}

impl From<std::io::Error> for Error {
    fn from(e: std::io::Error) -> Self {
        Error::new(ErrorKind::Io, e.to_string())
    }
}

pub type Result<T> = std::result::Result<T, Error>;

/// Fails with `InvalidArgument` unless `value` is finite.
pub fn check_finite(name: &str, value: f64) -> Result<()> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(Error::invalid(format!(
            "{name} must be finite, got {value}"
        )))
    }
}

/// Fails with `InvalidArgument` unless `value` is finite and strictly positive.
pub fn check_positive(name: &str, value: f64) -> Result<()> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(Error::invalid(format!(
            "{name} must be finite and > 0, got {value}"
        )))
    }
}
