//! The parallel node sums' primitives: write access to one grid's node storage from several
//! threads at once. This file and the SIMD kernels (`shape/simd.rs`) are where the engine's
//! unsafe operations are defined.
//!
//! The one invariant every `unsafe` method here rests on, and which its callers state at each
//! call: **no two threads access the same element at once.** The schedulers provide it:
//! - the coloured block schedule ([`Bins::run_tasks`](super::Bins)): blocks of one colour are
//!   at least a stencil apart, so their particles' stencils write disjoint nodes;
//! - the active-node list: it holds each node once, so a parallel loop over it gives each node
//!   to one task;
//! - the prefix sums of the binning and the listing: every (block, chunk) gets its own slots.
//!
//! Bounds are checked (`assert!`) except in [`NodeScatter::touch_unchecked`] and
//! [`scatter_add`], whose callers check the whole stencil box first
//! ([`NodeScatter::check_box`]).

use super::GridNodes;
use crate::Vector;

/// Write access to the node fields of a [`GridNodes`] from several threads at once, for the
/// coloured particle-to-grid map: the caller guarantees that no two threads write the same node.
/// Nodes written are marked touched; [`GridNodes::collect_touched`] lists them afterwards. The
/// slots of nodes listed before the scatter (by VC) stay readable.
#[derive(Clone, Copy)]
pub struct NodeScatter<'a, const D: usize> {
    pub mass: *mut f64,
    pub momentum: *mut Vector<D>,
    pub force: *mut Vector<D>,
    /// Null when the field is not kept.
    pub mass_gradient: *mut Vector<D>,
    /// Null when the field is not kept.
    pub body_force: *mut Vector<D>,
    touched: *mut bool,
    /// Slots of the nodes listed before the scatter.
    pub slot: &'a [u32],
    len: usize,
}

// SAFETY: the pointers address the node storage of one `GridNodes`, borrowed mutably
// for the
// scatter's lifetime; the callers write disjoint nodes from different threads (colours).
unsafe impl<const D: usize> Sync for NodeScatter<'_, D> {}
// SAFETY: as for `Sync`: moving the pointers to another thread changes nothing of the above.
unsafe impl<const D: usize> Send for NodeScatter<'_, D> {}

impl<'a, const D: usize> NodeScatter<'a, D> {
    /// Access to all fields of `nodes` (which stays mutably borrowed while this lives).
    pub fn new(nodes: &'a mut GridNodes<D>) -> Self {
        let opt = |v: &mut Vec<Vector<D>>| {
            if v.is_empty() {
                std::ptr::null_mut()
            } else {
                v.as_mut_ptr()
            }
        };
        NodeScatter {
            mass: nodes.mass.as_mut_ptr(),
            momentum: nodes.momentum.as_mut_ptr(),
            force: nodes.force.as_mut_ptr(),
            mass_gradient: opt(&mut nodes.mass_gradient),
            body_force: opt(&mut nodes.body_force),
            touched: nodes.touched.as_mut_ptr(),
            slot: &nodes.slot,
            len: nodes.mass.len(),
        }
    }

    /// Marks node `n` touched.
    ///
    /// # Safety
    /// No other thread writes node `n` during the scatter.
    #[inline(always)]
    pub unsafe fn touch(&self, n: usize) {
        // SAFETY: the caller keeps this function's `# Safety` contract (no other thread
        // accesses these elements meanwhile); the bounds are asserted above or were checked by
        // `NodeScatter::check_box`.
        unsafe {
            assert!(n < self.len);
            *self.touched.add(n) = true;
        }
    }

    /// Checks that the box of `width` nodes per axis from storage index `base` (with the
    /// given strides) lies inside the node storage, so that [`NodeScatter::touch_unchecked`]
    /// and the sums may address it.
    #[inline(always)]
    pub fn check_box(&self, base: usize, strides: &[usize; D], width: usize) {
        let last = base + strides.iter().map(|s| (width - 1) * s).sum::<usize>();
        assert!(last < self.len);
    }

    /// Marks node `n` touched, without the bounds check of [`NodeScatter::touch`].
    ///
    /// # Safety
    /// As [`NodeScatter::touch`], and `n` lies in a box [`NodeScatter::check_box`] accepted.
    #[inline(always)]
    pub unsafe fn touch_unchecked(&self, n: usize) {
        // SAFETY: the caller keeps this function's `# Safety` contract (no other thread
        // accesses these elements meanwhile); the bounds are asserted above or were checked by
        // `NodeScatter::check_box`.
        unsafe {
            *self.touched.add(n) = true;
        }
    }
}

/// Write access to disjoint parts of one slice from several threads (per-node storage of the
/// coloured sums); the caller guarantees that no two threads touch the same element.
pub struct SharedSlice<'a, T> {
    ptr: *mut T,
    len: usize,
    _slice: std::marker::PhantomData<&'a mut [T]>,
}

// SAFETY: see the type's documentation; every access goes through `range`, whose callers
// guarantee disjointness.
unsafe impl<T: Send> Sync for SharedSlice<'_, T> {}

impl<'a, T> SharedSlice<'a, T> {
    pub fn new(slice: &'a mut [T]) -> Self {
        SharedSlice {
            ptr: slice.as_mut_ptr(),
            len: slice.len(),
            _slice: std::marker::PhantomData,
        }
    }

    /// Length of the slice.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether the slice is empty.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The elements `start .. start + len`.
    ///
    /// # Safety
    /// No other thread accesses these elements while the returned slice lives.
    #[allow(clippy::mut_from_ref)]
    #[inline(always)]
    pub unsafe fn range(&self, start: usize, len: usize) -> &mut [T] {
        // SAFETY: the caller keeps this function's `# Safety` contract (no other thread
        // accesses these elements meanwhile); the bounds are asserted above or were checked by
        // `NodeScatter::check_box`.
        unsafe {
            assert!(start + len <= self.len);
            std::slice::from_raw_parts_mut(self.ptr.add(start), len)
        }
    }

    /// The address of element `i` (not dereferenced).
    #[inline(always)]
    pub fn as_ptr_at(&self, i: usize) -> *const T {
        self.ptr.wrapping_add(i)
    }

    /// Element `i`.
    ///
    /// # Safety
    /// No other thread accesses element `i` while the returned reference lives.
    #[allow(clippy::mut_from_ref)]
    #[inline(always)]
    pub unsafe fn at(&self, i: usize) -> &mut T {
        // SAFETY: the caller keeps this function's `# Safety` contract (no other thread
        // accesses these elements meanwhile); the bounds are asserted above or were checked by
        // `NodeScatter::check_box`.
        unsafe {
            assert!(i < self.len);
            &mut *self.ptr.add(i)
        }
    }
}

/// Whether a node with this touched mark and mass was written this step, and so belongs in the
/// active list: the one rule of the serial collection ([`GridNodes::collect_touched`]) and the
/// parallel one ([`GridNodes::count_written`], [`NodeList::is_written`]), which must agree.
#[inline(always)]
pub(super) fn is_written(touched: bool, mass: f64) -> bool {
    touched | (mass != 0.0)
}

/// Puts nodes into the active list from several threads ([`GridNodes::list`]).
pub struct NodeList<'a> {
    pub(super) active: SharedSlice<'a, usize>,
    pub(super) slot: SharedSlice<'a, u32>,
    pub(super) touched: SharedSlice<'a, bool>,
    pub(super) mass: &'a [f64],
}

impl NodeList<'_> {
    /// Whether [`GridNodes::collect_touched`] would list node `n` (marked touched or given
    /// mass).
    ///
    /// # Safety
    /// No other thread puts node `n` meanwhile.
    #[inline(always)]
    pub unsafe fn is_written(&self, n: usize) -> bool {
        // SAFETY: the caller keeps this function's `# Safety` contract (no other thread
        // accesses these elements meanwhile); the bounds are asserted above or were checked by
        // `NodeScatter::check_box`.
        unsafe { is_written(*self.touched.at(n), self.mass[n]) }
    }

    /// Lists node `n` at position `k` of `active`, marked touched: what
    /// [`GridNodes::collect_touched`] does for the `k`-th node it lists.
    ///
    /// # Safety
    /// No other thread puts a node at `k` or puts node `n`.
    #[inline(always)]
    pub unsafe fn put(&self, k: usize, n: usize) {
        // SAFETY: the caller keeps this function's `# Safety` contract (no other thread
        // accesses these elements meanwhile); the bounds are asserted above or were checked by
        // `NodeScatter::check_box`.
        unsafe {
            *self.active.at(k) = n;
            *self.slot.at(n) = k as u32;
            *self.touched.at(n) = true;
        }
    }
}

/// `*field[n] += value` for a field pointer of a [`NodeScatter`].
///
/// # Safety
/// `field` is one of the scatter's non-null pointers, `n` was checked by [`NodeScatter::touch`]
/// and no other thread writes node `n` during the scatter.
#[inline(always)]
pub unsafe fn scatter_add<T: std::ops::AddAssign>(field: *mut T, n: usize, value: T) {
    // SAFETY: the caller keeps this function's `# Safety` contract (no other thread
    // accesses these elements meanwhile); the bounds are asserted above or were checked by
    // `NodeScatter::check_box`.
    unsafe {
        *field.add(n) += value;
    }
}

/// Small tests of the primitives from several threads, fast enough for Miri
/// (`scripts/test-miri.sh`), which checks that the accesses are in bounds, aligned and free of
/// data races under the invariant above. Plain scoped threads stand in for rayon's tasks (whose
/// own internals Miri's aliasing model flags).
#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::Grid;
    use std::thread;

    /// A 2D grid of 4 × 4 cells (7 × 7 nodes with the ghost layers) and its node storage.
    fn nodes() -> (Grid<2>, GridNodes<2>) {
        let grid = Grid::<2>::new(Vector::zeros(), [4, 4], 0.25).unwrap();
        let mut nodes = GridNodes::<2>::default();
        nodes.ensure(&grid, false, false, false).unwrap();
        (grid, nodes)
    }

    /// Disjoint ranges and elements of one slice written from several threads: every element
    /// ends with the value its one writer gave it.
    #[test]
    fn disjoint_ranges_from_several_threads() {
        let mut v = vec![0usize; 48];
        let shared = SharedSlice::new(&mut v);
        thread::scope(|scope| {
            for k in 0..6 {
                let shared = &shared;
                scope.spawn(move || {
                    // SAFETY: thread `k` alone accesses elements `8k .. 8k + 8`.
                    let r = unsafe { shared.range(8 * k, 8) };
                    for (i, x) in r.iter_mut().enumerate() {
                        *x = 8 * k + i;
                    }
                });
            }
        });
        thread::scope(|scope| {
            for k in 0..2 {
                let shared = &shared;
                scope.spawn(move || {
                    for i in (2 * k..48).step_by(4) {
                        // SAFETY: thread `k` alone visits the indices `2k + 4j`.
                        unsafe { *shared.at(i) += 100 };
                    }
                });
            }
        });
        let expected: Vec<usize> = (0..48).map(|i| i + 100 * usize::from(i % 2 == 0)).collect();
        assert_eq!(v, expected);
    }

    /// The scatter's sums from several threads, each writing its own nodes, then the parallel
    /// listing: the same active list, slots and marks as the serial collection.
    #[test]
    fn scatter_then_list_from_several_threads() {
        let (grid, mut nodes) = nodes();
        let n = grid.node_count();
        let written: Vec<usize> = (0..n).filter(|i| i % 3 != 1).collect();
        {
            let out = NodeScatter::new(&mut nodes);
            thread::scope(|scope| {
                for part in written.chunks(written.len().div_ceil(3)) {
                    let out = &out;
                    scope.spawn(move || {
                        for &i in part {
                            // SAFETY: `written` lists each node once and the chunks are
                            // disjoint, so every node has one writer; `touch` checks the bound.
                            unsafe {
                                out.touch(i);
                                scatter_add(out.mass, i, 1.0 + i as f64);
                                scatter_add(out.momentum, i, Vector::<2>::new(i as f64, 2.0));
                            }
                        }
                    });
                }
            });
        }
        let mut serial = nodes.clone();
        for i in 0..n {
            serial.collect_touched(i);
        }
        // The parallel listing: a count per half, then each half puts its nodes from its offset.
        let halves = [0..n / 2, n / 2..n];
        let counts = halves.clone().map(|h| nodes.count_written(h));
        let list = nodes.list(counts[0] + counts[1]).unwrap();
        let offsets = [0, counts[0]];
        thread::scope(|scope| {
            for (h, offset) in halves.iter().zip(offsets) {
                let list = &list;
                scope.spawn(move || {
                    let mut k = offset;
                    for i in h.clone() {
                        // SAFETY: the halves are disjoint, and so are their stretches of
                        // `active`.
                        unsafe {
                            if list.is_written(i) {
                                list.put(k, i);
                                k += 1;
                            }
                        }
                    }
                });
            }
        });
        assert_eq!(nodes.active, serial.active);
        assert_eq!(nodes.active, written);
        for &i in &written {
            assert_eq!(nodes.slot(i), serial.slot(i));
            assert_eq!(nodes.mass[i], 1.0 + i as f64);
            assert_eq!(nodes.momentum[i], Vector::<2>::new(i as f64, 2.0));
        }
        nodes.reset();
        assert!(nodes.is_clear());
    }
}
