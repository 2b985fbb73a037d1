//! Status codes of the C API. The numbers are fixed: never reuse or renumber them.

use rkmpm::error::ErrorKind;

/// Result of every C API call that can fail. `RKMPM_OK` is 0; every other value names a kind of
/// failure, and `rkmpm_last_error_message` gives the details of the last failure on this thread.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RkmpmStatus {
    /// Success.
    RKMPM_OK = 0,
    /// A required pointer argument was NULL.
    RKMPM_ERR_NULL_POINTER = 1,
    /// An argument is out of range, not finite, misaligned or an unknown enum value.
    RKMPM_ERR_INVALID_ARGUMENT = 2,
    /// The output buffer is shorter than needed; nothing was written.
    RKMPM_ERR_BUFFER_TOO_SMALL = 3,
    /// The call is not allowed now (for example an option changed after the first step).
    RKMPM_ERR_INVALID_STATE = 4,
    /// A material id that was never added.
    RKMPM_ERR_UNKNOWN_MATERIAL = 5,
    /// A particle lies, or would move, outside the grid's domain.
    RKMPM_ERR_OUTSIDE_GRID = 6,
    /// The time step exceeds the critical (CFL 1) time step.
    RKMPM_ERR_UNSTABLE_TIME_STEP = 7,
    /// The step produced NaN or infinity; the last good state is kept.
    RKMPM_ERR_NON_FINITE = 8,
    /// The step produced an inverted particle (det F <= 0); the last good state is kept.
    RKMPM_ERR_INVERTED_PARTICLE = 9,
    /// The body-force callback returned non-zero or a non-finite value.
    RKMPM_ERR_CALLBACK = 10,
    /// A file could not be written or read.
    RKMPM_ERR_IO = 11,
    /// The feature or combination of options is not available (for example APIC with RK order >= 2).
    RKMPM_ERR_UNSUPPORTED = 12,
    /// An internal error (a caught panic); please report it.
    RKMPM_ERR_PANIC = 13,
    /// A checkpoint file is truncated, damaged (checksum) or not a checkpoint.
    RKMPM_ERR_CORRUPT_FILE = 14,
    /// Storage could not be allocated (for example a grid too large for the memory); the
    /// simulation is unchanged.
    RKMPM_ERR_OUT_OF_MEMORY = 15,
}

impl RkmpmStatus {
    pub const ALL: [RkmpmStatus; 16] = [
        RkmpmStatus::RKMPM_OK,
        RkmpmStatus::RKMPM_ERR_NULL_POINTER,
        RkmpmStatus::RKMPM_ERR_INVALID_ARGUMENT,
        RkmpmStatus::RKMPM_ERR_BUFFER_TOO_SMALL,
        RkmpmStatus::RKMPM_ERR_INVALID_STATE,
        RkmpmStatus::RKMPM_ERR_UNKNOWN_MATERIAL,
        RkmpmStatus::RKMPM_ERR_OUTSIDE_GRID,
        RkmpmStatus::RKMPM_ERR_UNSTABLE_TIME_STEP,
        RkmpmStatus::RKMPM_ERR_NON_FINITE,
        RkmpmStatus::RKMPM_ERR_INVERTED_PARTICLE,
        RkmpmStatus::RKMPM_ERR_CALLBACK,
        RkmpmStatus::RKMPM_ERR_IO,
        RkmpmStatus::RKMPM_ERR_UNSUPPORTED,
        RkmpmStatus::RKMPM_ERR_PANIC,
        RkmpmStatus::RKMPM_ERR_CORRUPT_FILE,
        RkmpmStatus::RKMPM_ERR_OUT_OF_MEMORY,
    ];

    /// A NUL-terminated static description.
    pub fn describe(self) -> &'static str {
        match self {
            RkmpmStatus::RKMPM_OK => "ok\0",
            RkmpmStatus::RKMPM_ERR_NULL_POINTER => "null pointer\0",
            RkmpmStatus::RKMPM_ERR_INVALID_ARGUMENT => "invalid argument\0",
            RkmpmStatus::RKMPM_ERR_BUFFER_TOO_SMALL => "buffer too small\0",
            RkmpmStatus::RKMPM_ERR_INVALID_STATE => "invalid state\0",
            RkmpmStatus::RKMPM_ERR_UNKNOWN_MATERIAL => "unknown material\0",
            RkmpmStatus::RKMPM_ERR_OUTSIDE_GRID => "particle outside the grid\0",
            RkmpmStatus::RKMPM_ERR_UNSTABLE_TIME_STEP => "time step above the stable limit\0",
            RkmpmStatus::RKMPM_ERR_NON_FINITE => "non-finite value in the step\0",
            RkmpmStatus::RKMPM_ERR_INVERTED_PARTICLE => "inverted particle (det F <= 0)\0",
            RkmpmStatus::RKMPM_ERR_CALLBACK => "callback failed\0",
            RkmpmStatus::RKMPM_ERR_IO => "input/output error\0",
            RkmpmStatus::RKMPM_ERR_UNSUPPORTED => "not supported\0",
            RkmpmStatus::RKMPM_ERR_PANIC => "internal error (panic)\0",
            RkmpmStatus::RKMPM_ERR_CORRUPT_FILE => "corrupt checkpoint file\0",
            RkmpmStatus::RKMPM_ERR_OUT_OF_MEMORY => "out of memory\0",
        }
    }
}

impl From<ErrorKind> for RkmpmStatus {
    fn from(kind: ErrorKind) -> Self {
        match kind {
            ErrorKind::InvalidArgument => RkmpmStatus::RKMPM_ERR_INVALID_ARGUMENT,
            ErrorKind::InvalidState => RkmpmStatus::RKMPM_ERR_INVALID_STATE,
            ErrorKind::UnknownMaterial => RkmpmStatus::RKMPM_ERR_UNKNOWN_MATERIAL,
            ErrorKind::OutsideGrid => RkmpmStatus::RKMPM_ERR_OUTSIDE_GRID,
            ErrorKind::UnstableTimeStep => RkmpmStatus::RKMPM_ERR_UNSTABLE_TIME_STEP,
            ErrorKind::NonFinite => RkmpmStatus::RKMPM_ERR_NON_FINITE,
            ErrorKind::InvertedParticle => RkmpmStatus::RKMPM_ERR_INVERTED_PARTICLE,
            ErrorKind::Callback => RkmpmStatus::RKMPM_ERR_CALLBACK,
            ErrorKind::Io => RkmpmStatus::RKMPM_ERR_IO,
            ErrorKind::Unsupported => RkmpmStatus::RKMPM_ERR_UNSUPPORTED,
            ErrorKind::CorruptFile => RkmpmStatus::RKMPM_ERR_CORRUPT_FILE,
            ErrorKind::OutOfMemory => RkmpmStatus::RKMPM_ERR_OUT_OF_MEMORY,
        }
    }
}
