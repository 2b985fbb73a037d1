//! The one gate every exported function goes through: panics are caught, errors become a status,
//! and the message of the last failure is kept per thread. Also the shared argument checkers.

use super::status::RkmpmStatus;
use rkmpm::error::Error;
use std::cell::RefCell;
use std::panic::{catch_unwind, AssertUnwindSafe};

/// An error on its way to C: a status and a message.
pub struct Failure {
    pub status: RkmpmStatus,
    pub message: String,
}

impl Failure {
    pub fn new(status: RkmpmStatus, message: impl Into<String>) -> Self {
        Failure {
            status,
            message: message.into(),
        }
    }
}

impl From<Error> for Failure {
    fn from(e: Error) -> Self {
        Failure::new(e.kind.into(), e.message)
    }
}

thread_local! {
    static LAST_ERROR: RefCell<String> = const { RefCell::new(String::new()) };
}

/// The message of the last failed call on this thread (empty if none failed).
pub fn last_error() -> String {
    LAST_ERROR.with(|e| e.borrow().clone())
}

fn set_last_error(function: &str, message: &str) {
    LAST_ERROR.with(|e| *e.borrow_mut() = format!("{function}: {message}"));
}

/// Runs `body`, turning an `Err` or a panic into a status and recording its message.
pub fn gate(function: &str, body: impl FnOnce() -> Result<(), Failure>) -> RkmpmStatus {
    match catch_unwind(AssertUnwindSafe(body)) {
        Ok(Ok(())) => RkmpmStatus::RKMPM_OK,
        Ok(Err(f)) => {
            set_last_error(function, &f.message);
            f.status
        }
        Err(panic) => {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".into());
            set_last_error(function, &format!("internal error: {what}"));
            RkmpmStatus::RKMPM_ERR_PANIC
        }
    }
}

/// Fails with `RKMPM_ERR_NULL_POINTER` naming `name` when `ptr` is NULL, and with
/// `RKMPM_ERR_INVALID_ARGUMENT` when it is misaligned for `T`.
pub fn check_ptr<T>(name: &str, ptr: *const T) -> Result<(), Failure> {
    if ptr.is_null() {
        return Err(Failure::new(
            RkmpmStatus::RKMPM_ERR_NULL_POINTER,
            format!("{name} is NULL"),
        ));
    }
    if !(ptr as usize).is_multiple_of(std::mem::align_of::<T>()) {
        return Err(Failure::new(
            RkmpmStatus::RKMPM_ERR_INVALID_ARGUMENT,
            format!("{name} is not aligned for its type"),
        ));
    }
    Ok(())
}

/// `count * per`, failing on overflow or on more elements than a slice may hold.
pub fn checked_len(name: &str, count: usize, per: usize) -> Result<usize, Failure> {
    count
        .checked_mul(per)
        .filter(|&n| n <= isize::MAX as usize / std::mem::size_of::<f64>())
        .ok_or_else(|| {
            Failure::new(
                RkmpmStatus::RKMPM_ERR_INVALID_ARGUMENT,
                format!("{name}: count {count} × {per} is too large"),
            )
        })
}

/// A slice of `len` values at a checked pointer (an empty slice for `len == 0`, whatever the pointer).
///
/// # Safety
/// `ptr` must point to `len` readable values when `len > 0`.
pub unsafe fn slice<'a, T>(name: &str, ptr: *const T, len: usize) -> Result<&'a [T], Failure> {
    if len == 0 {
        return Ok(&[]);
    }
    check_ptr(name, ptr)?;
    // SAFETY: non-NULL and aligned (checked); `len` readable values by the contract above.
    Ok(unsafe { std::slice::from_raw_parts(ptr, len) })
}

/// The option kind (or field) `K` whose C code is `code`; `RKMPM_ERR_INVALID_ARGUMENT` naming
/// `name` for a code with no meaning.
pub fn kind_of<K: TryFrom<u32>>(name: &str, code: u32) -> Result<K, Failure> {
    K::try_from(code).map_err(|_| unknown_enum(name, code))
}

/// Fails with `RKMPM_ERR_INVALID_ARGUMENT` for an enum value C passed that has no meaning.
pub fn unknown_enum(name: &str, value: impl std::fmt::Display) -> Failure {
    Failure::new(
        RkmpmStatus::RKMPM_ERR_INVALID_ARGUMENT,
        format!("{name} = {value} is not a known value"),
    )
}
