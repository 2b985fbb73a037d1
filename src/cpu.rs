//! The processor's wider vector instructions for the hot loops, chosen at run time.
//!
//! The library is built for the portable x86-64 baseline (SSE2: 16 registers of two `f64`, no
//! three-operand forms). Where the processor has AVX2 and FMA (x86-64-v3, every x86 server
//! processor since about 2015), the bodies of the particle loops run as code compiled for them
//! ([`Lanes::wide`]): fewer moves and spills. No floating-point operation changes (Rust never fuses a
//! multiply and an add on its own and never reorders a sum), so both paths give the same bits.
//!
//! The choice is a value, [`Lanes`], that a simulation holds (`Sim::set_fast_paths`) and its
//! stencils carry into the loops; a `Lanes` that takes the AVX2 path exists only on a processor
//! that has AVX2 and FMA ([`Lanes::detect`]), which is what makes the calls compiled for them
//! sound. `RKMPM_PORTABLE=1` in the environment (read once) makes `detect` keep the baseline
//! too, for a whole process. AVX-512 was tried too (BENCHMARKS.md): it made the 3D gather
//! slower and particle to grid no faster, so it is not a path.

use std::sync::OnceLock;

/// The instruction set of the hot loops: the portable baseline, or AVX2 and FMA.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Lanes {
    /// Only true when the processor has AVX2 and FMA (the one invariant the `unsafe` calls of
    /// [`Lanes::wide`] and the AVX2 kernels rest on): set by [`Lanes::detect`] alone.
    avx2: bool,
}

impl Lanes {
    /// The portable baseline code.
    pub const fn baseline() -> Lanes {
        Lanes { avx2: false }
    }

    /// AVX2 and FMA when the processor has them and `RKMPM_PORTABLE=1` is not set; else the
    /// baseline. Detected once per process.
    pub fn detect() -> Lanes {
        static DETECTED: OnceLock<bool> = OnceLock::new();
        let avx2 = *DETECTED.get_or_init(|| {
            let portable = std::env::var_os("RKMPM_PORTABLE").is_some_and(|v| v == "1");
            #[cfg(target_arch = "x86_64")]
            let found = is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma");
            #[cfg(not(target_arch = "x86_64"))]
            let found = false;
            found && !portable
        });
        Lanes { avx2 }
    }

    /// [`Lanes::detect`] when `vector_instructions`, else the baseline.
    pub fn chosen(vector_instructions: bool) -> Lanes {
        match vector_instructions {
            true => Lanes::detect(),
            false => Lanes::baseline(),
        }
    }

    /// Whether these lanes take the AVX2 path (then the processor has AVX2 and FMA).
    #[inline(always)]
    pub fn avx2(self) -> bool {
        self.avx2
    }

    /// Runs `f`, compiled for AVX2 and FMA on the AVX2 path (see the module).
    ///
    /// `f` should be the body of a chunk of work (a block of particles), not one particle: the
    /// choice is a call that is not inlined. What `f` calls must be inlined into it to be
    /// compiled for AVX2 too ([`inlined`], `#[inline(always)]`).
    #[inline(always)]
    pub fn wide<R>(self, f: impl FnOnce() -> R) -> R {
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: `avx2` is true only when the processor has AVX2 and FMA (`detect`), the
            // features `avx2` enables.
            return unsafe { avx2(f) };
        }
        f()
    }

    /// Asks the processor to bring the cache lines of `count` values from `first` on into its
    /// cache for writing (`prefetchw`), on the AVX2 path; does nothing otherwise.
    ///
    /// The particle loops write their results to arrays that are not in the cache (the new
    /// state of grid to particle, 136 bytes per particle in 2D, is several times the L2 cache
    /// already at 10^5 particles), and each line written waits for its read for ownership;
    /// asked for a few chunks ahead, the lines are there when the stores come. `prefetchw`
    /// executes as a no-operation on Intel processors before Broadwell, and every processor
    /// that takes the AVX2 path (Haswell or later) decodes it; a prefetch reads nothing and
    /// never faults, so `first` need not be valid.
    #[inline(always)]
    pub fn prefetch_for_write<T>(self, first: *const T, count: usize) {
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
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
}

/// Hands `f` back. On stable Rust a closure can carry `#[inline(always)]` only as an argument,
/// so `let body = cpu::inlined(#[inline(always)] |p| …)` marks a closure that [`Lanes::wide`]'s
/// bodies call: otherwise the compiler may keep it out of line, compiled for the baseline.
#[inline(always)]
pub fn inlined<F>(f: F) -> F {
    f
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
        super::Lanes::detect().prefetch_for_write(v.as_ptr(), v.len());
        super::Lanes::detect().prefetch_for_write(std::ptr::null::<f64>(), 1000);
        super::Lanes::detect().prefetch_for_write(usize::MAX as *const [f64; 8], 2);
        super::Lanes::detect().prefetch_for_write(v.as_ptr().wrapping_add(1 << 40), 64);
        super::Lanes::detect().prefetch_for_write((usize::MAX - 70) as *const u8, 8);
        assert!(v.iter().all(|&x| x == 1.5));
    }
}
