//! The processor's wider vector instructions for the hot loops, chosen at run time.
//!
//! The library is built for the portable x86-64 baseline (SSE2: 16 registers of two `f64`, no
//! three-operand forms). Where the processor has AVX2 and FMA (x86-64-v3, every x86 server
//! processor since about 2015), the bodies of the particle loops run as code compiled for them
//! ([`wide`]): fewer moves and spills. No floating-point operation changes (Rust never fuses a
//! multiply and an add on its own and never reorders a sum), so both paths give the same bits.
//!
//! `RKMPM_PORTABLE=1` in the environment (read once) or [`use_baseline`] keeps the baseline code,
//! so a benchmark can compare the two with one build. AVX-512 was tried too (BENCHMARKS.md): it made the 3D gather
//! slower and gained about 1% elsewhere, so it is not a path.

use std::sync::atomic::{AtomicU8, Ordering};

/// Runs `f`, compiled for AVX2 and FMA when the processor has them (see the module).
///
/// `f` should be the body of a chunk of work (a block of particles), not one particle: the
/// choice is a call that is not inlined. What `f` calls must be inlined into it to be compiled
/// for AVX2 too ([`inlined`], `#[inline(always)]`).
#[inline(always)]
pub fn wide<R>(f: impl FnOnce() -> R) -> R {
    #[cfg(target_arch = "x86_64")]
    if has_avx2() {
        // SAFETY: the processor has the features `avx2` enables (checked by `has_avx2`).
        return unsafe { avx2(f) };
    }
    f()
}

/// Hands `f` back. On stable Rust a closure can carry `#[inline(always)]` only as an argument,
/// so `let body = cpu::inlined(#[inline(always)] |p| …)` marks a closure that [`wide`]'s bodies
/// call: otherwise the compiler may keep it out of line, compiled for the baseline.
#[inline(always)]
pub fn inlined<F>(f: F) -> F {
    f
}

/// Asks the processor to bring the cache lines of `count` values from `first` on into its
/// cache for writing (`prefetchw`), on the AVX2 path (see below); does nothing otherwise.
///
/// The particle loops write their results to arrays that are not in the cache (the new state of
/// grid to particle, 136 bytes per particle in 2D, is several times the L2 cache already at 10^5
/// particles), and each line written waits for its read for ownership; asked for a few chunks
/// ahead, the lines are there when the stores come. `prefetchw` executes as a no-operation on
/// Intel processors before Broadwell, and every processor that takes the AVX2 path (Haswell or
/// later) decodes it; a prefetch reads nothing and never faults, so `first` need not be valid.
#[inline(always)]
pub fn prefetch_for_write<T>(first: *const T, count: usize) {
    #[cfg(target_arch = "x86_64")]
    if has_avx2() {
        let start = first as usize;
        let end = start.wrapping_add(count * std::mem::size_of::<T>());
        let mut line = start & !63;
        while line < end {
            // SAFETY: a prefetch reads nothing and cannot fault, whatever the address.
            unsafe {
                std::arch::asm!(
                    "prefetchw [{0}]",
                    in(reg) line,
                    options(nostack, preserves_flags, readonly)
                );
            }
            match line.checked_add(64) {
                Some(next) => line = next,
                None => break,
            }
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (first, count);
}

/// Whether [`wide`] takes the AVX2 path on this processor and in this environment.
#[inline]
pub fn has_avx2() -> bool {
    match CHOICE.load(Ordering::Relaxed) {
        BASELINE => false,
        AVX2 => true,
        _ => {
            let portable = std::env::var_os("RKMPM_PORTABLE").is_some_and(|v| v == "1");
            choose(portable)
        }
    }
}

/// Keeps the baseline code (`true`), or goes back to the processor's choice (`false`): as
/// `RKMPM_PORTABLE`, for comparisons within one process. Both give the same results.
pub fn use_baseline(yes: bool) {
    choose(yes);
}

const UNSET: u8 = 0;
const BASELINE: u8 = 1;
const AVX2: u8 = 2;
static CHOICE: AtomicU8 = AtomicU8::new(UNSET);

fn choose(baseline: bool) -> bool {
    #[cfg(target_arch = "x86_64")]
    let avx2 = !baseline && is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma");
    #[cfg(not(target_arch = "x86_64"))]
    let avx2 = false;
    CHOICE.store(if avx2 { AVX2 } else { BASELINE }, Ordering::Relaxed);
    avx2
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx,avx2,fma")]
unsafe fn avx2<R>(f: impl FnOnce() -> R) -> R {
    f()
}

#[cfg(test)]
mod tests {
    /// A prefetch reads nothing: addresses outside any allocation (null, the end of the address
    /// space, a range that wraps around) neither fault nor change memory.
    #[test]
    fn prefetch_for_write_never_faults_and_changes_nothing() {
        let v = vec![1.5f64; 100];
        super::prefetch_for_write(v.as_ptr(), v.len());
        super::prefetch_for_write(std::ptr::null::<f64>(), 1000);
        super::prefetch_for_write(usize::MAX as *const [f64; 8], 2);
        super::prefetch_for_write(v.as_ptr().wrapping_add(1 << 40), 64);
        super::prefetch_for_write((usize::MAX - 70) as *const u8, 8);
        assert!(v.iter().all(|&x| x == 1.5));
    }
}
