//! Particles binned by grid block, for a particle-to-grid map that runs in parallel without locks
//! and gives the same bits with any number of threads.
//!
//! A block is `B_a` nodes along axis `a` (128 along axis 0, 4 along the others; more for wide
//! stencils). A particle belongs to the block of the first node of its stencil box
//! (`ShapeFunction::stencil_origin`), so with `B_a ≥ W − 1` (`W` stencil nodes per axis) its
//! stencil lies in its own block and the next one along each axis. Blocks take one of
//! `2^D` colours by the parity of their block coordinates; two blocks of one colour are at least
//! two blocks apart along some axis, so they write disjoint nodes. The map takes the blocks colour
//! by colour, the particles of a block in storage order, and a block starts once the blocks of
//! earlier colours that share nodes with it (its neighbours) have ended ([`Bins::run_tasks`]):
//! blocks of one colour run in parallel, and every node's sum is taken in an order fixed by the
//! particles' positions and storage order (which the step's sorts set from positions alone),
//! never by the number of threads. When the particles
//! occupy enough rows of blocks (`MIN_ROWS`), the map's tasks are whole rows instead (the blocks
//! along axis 0, in turn), coloured by the parity of the other block coordinates
//! ([`Bins::tasks`]): longer runs and half the colours.
//!
//! The occupied blocks also give the node blocks a step touches (each occupied block and its
//! upper neighbours), so the list of active nodes is collected without visiting empty blocks.

use super::{Grid, GridNodes, SharedSlice};
use crate::Vector;
use rayon::prelude::*;

/// Nodes per block side, at least.
const MIN_BLOCK: usize = 4;
/// Nodes per block along axis 0, the fastest storage axis of the grid and, usually, of the
/// particles (lattices are added with axis 0 fastest): a block's particles then lie in long runs
/// of the particle arrays. Particle to grid gets faster as blocks grow along axis 0 and levels
/// off at this length; blocks as long as the grid would be faster still on one thread, but leave
/// too few blocks per colour to share among threads when a body is thin along axis 1.
const LONG_BLOCK: usize = 128;

/// Occupied rows of blocks from which particle to grid runs by rows ([`Bins::tasks`]): a row
/// is a longer run of particles and nodes than a block, and there are half as many colours
/// (faster in 2D, the same in 3D). Fewer rows would leave too few tasks per colour to share
/// among threads. The choice depends on the particles only, not on the number of threads.
const MIN_ROWS: usize = 32;

/// Average run of consecutive particle slots in block order below which the particles are
/// stored anew in that order (`Bins::is_scattered`).
const SORTED_RUN: usize = 512;

/// The blocks of a grid for stencils `width` nodes per axis: their sides (powers of two, so that
/// a particle's block is a shift of its first node's index) and how many there are per axis.
#[derive(Debug, Clone, Copy)]
pub struct BlockLayout<const D: usize> {
    /// Nodes per block side, per axis.
    block: [usize; D],
    /// Blocks per axis (covering every stored node).
    blocks: [usize; D],
    shift: [u32; D],
    dims: [usize; D],
    ghost: i64,
}

impl<const D: usize> Default for BlockLayout<D> {
    /// No blocks (before the first binning).
    fn default() -> Self {
        BlockLayout {
            block: [MIN_BLOCK; D],
            blocks: [0; D],
            shift: [0; D],
            dims: [0; D],
            ghost: 0,
        }
    }
}

impl<const D: usize> BlockLayout<D> {
    pub fn new(width: usize, grid: &Grid<D>) -> Self {
        let side = (width.max(2) - 1).max(MIN_BLOCK).next_power_of_two();
        let long = side.max(LONG_BLOCK);
        let block: [usize; D] = std::array::from_fn(|a| if a == 0 { long } else { side });
        let dims = grid.dims();
        let blocks: [usize; D] = std::array::from_fn(|a| dims[a].div_ceil(block[a]));
        assert!(blocks.iter().product::<usize>() < u32::MAX as usize);
        BlockLayout {
            block,
            blocks,
            shift: block.map(|b| b.trailing_zeros()),
            dims,
            ghost: grid.ghost_layers() as i64,
        }
    }

    /// The block of a particle whose stencil starts at the integer node index `first` (clamped
    /// to the grid: a particle outside it is refused by the step's checks before it is binned).
    #[inline(always)]
    pub fn key(&self, first: &[i64; D]) -> u32 {
        let mut key = 0usize;
        for a in (0..D).rev() {
            let s = (first[a] + self.ghost).clamp(0, self.dims[a] as i64 - 1) as usize;
            key = key * self.blocks[a] + (s >> self.shift[a]);
        }
        key as u32
    }
}

/// The runs of equal consecutive keys: each key and how many times it repeats. Sorted particles
/// keep their blocks in long runs, so the counting sort adds and places a run at once instead of
/// incrementing a block's count particle by particle: that is a chain of loads and stores to
/// one address, a store-to-load forwarding latency per particle on processors that do not
/// rename memory.
fn runs(keys: &[u32]) -> impl Iterator<Item = (u32, u32)> + '_ {
    let mut rest = keys;
    std::iter::from_fn(move || {
        let (&k, tail) = rest.split_first()?;
        let run = 1 + tail.iter().take_while(|&&t| t == k).count();
        rest = &rest[run..];
        Some((k, run as u32))
    })
}

/// Particles sorted by block, the occupied blocks by colour, and the node blocks they touch.
#[derive(Debug, Clone)]
pub struct Bins<const D: usize> {
    /// The blocks of the last binning.
    layout: BlockLayout<D>,
    /// Block of each particle (when `Bins::compute` found them).
    keys: Vec<u32>,
    /// Particle indices, block by block (ascending keys), ascending within a block.
    pub order: Vec<u32>,
    /// Occupied blocks in ascending key order: key and the range of `order` they hold.
    pub occupied: Vec<(u32, std::ops::Range<usize>)>,
    /// Indices into `occupied`, per colour.
    pub colours: Vec<Vec<u32>>,
    /// The tasks of particle to grid, by colour: ranges of `order` whose particles one thread
    /// maps in turn, while the tasks of one colour run in parallel (they write disjoint nodes).
    /// With at least `MIN_ROWS` occupied rows of blocks (the blocks along axis 0 that share
    /// their other coordinates), a task is a row and the colour is the parity of the row's
    /// coordinates (`2^(D−1)` colours, rows of one colour being two blocks apart); otherwise
    /// (a body thin across axis 0) a task is a block, coloured as `colours`.
    pub tasks: Vec<Vec<std::ops::Range<usize>>>,
    /// For each task of `tasks` taken colour by colour (`k`-th overall), the earlier tasks it
    /// shares nodes with: `waits[wait_start[k]..wait_start[k + 1]]` ([`Bins::run_tasks`]).
    waits: Vec<u32>,
    wait_start: Vec<u32>,
    /// Node blocks touched by some particle's stencil, ascending.
    pub node_blocks: Vec<u32>,
    /// Scratch: particles per block, then start offsets; and node-block marks.
    counts: Vec<u32>,
    marks: Vec<bool>,
}

impl<const D: usize> Default for Bins<D> {
    fn default() -> Self {
        Bins {
            layout: BlockLayout::default(),
            keys: Vec::new(),
            order: Vec::new(),
            occupied: Vec::new(),
            colours: Vec::new(),
            tasks: Vec::new(),
            waits: Vec::new(),
            wait_start: Vec::new(),
            node_blocks: Vec::new(),
            counts: Vec::new(),
            marks: Vec::new(),
        }
    }
}

impl<const D: usize> Bins<D> {
    /// Bins the particles at `x` on `grid` for a shape function of `width` stencil nodes per
    /// axis, from the first node of each one's stencil, `first_node(x)` of its position `x` in
    /// cell units (`ShapeFunction::stencil_origin`; the B-spline stencils find the keys with
    /// their factors and call [`Bins::compute_from_keys`]).
    pub fn compute(
        &mut self,
        width: usize,
        grid: &Grid<D>,
        x: &[Vector<D>],
        first_node: impl Fn(&Vector<D>) -> [i64; D] + Sync,
    ) {
        let layout = BlockLayout::new(width, grid);
        let mut keys = std::mem::take(&mut self.keys);
        keys.resize(x.len(), 0);
        keys.par_iter_mut().zip(x).for_each(|(k, x)| {
            *k = layout.key(&first_node(&grid.to_cell_units(x)));
        });
        self.compute_from_keys(&layout, &keys);
        self.keys = keys;
    }

    /// Bins the particles whose blocks under `layout` are `keys` ([`BlockLayout::key`] of each
    /// one's first stencil node; the B-spline stencils compute them with their factors).
    pub fn compute_from_keys(&mut self, layout: &BlockLayout<D>, keys: &[u32]) {
        let n = keys.len();
        assert!(n < u32::MAX as usize);
        self.layout = *layout;
        let blocks = layout.blocks;
        let total: usize = blocks.iter().product();
        // Counting sort (stable: particles of a block stay in index order), in parallel over
        // chunks of the particles: each chunk counts its keys, a prefix over (block, chunk)
        // gives each chunk its slots in every block, and the chunks place their particles at
        // once. A stable sort has one result, so the order does not depend on the chunks.
        // Chunks of at least 2^17 particles: below that the sort runs on one thread, as each
        // parallel pass costs more than it saves there.
        let chunk = n.div_ceil(rayon::current_num_threads().max(1)).max(1 << 17);
        let chunks = n.div_ceil(chunk).max(1);
        self.counts.clear();
        self.counts.resize(chunks * total, 0);
        self.counts
            .par_chunks_mut(total)
            .zip(keys.par_chunks(chunk))
            .for_each(|(counts, keys)| {
                for (k, run) in runs(keys) {
                    counts[k as usize] += run;
                }
            });
        self.occupied.clear();
        let mut start = 0u32;
        for b in 0..total {
            let first = start;
            for c in 0..chunks {
                let count = &mut self.counts[c * total + b];
                (*count, start) = (start, start + *count);
            }
            if start > first {
                self.occupied
                    .push((b as u32, first as usize..start as usize));
            }
        }
        self.order.resize(n, 0);
        let order = SharedSlice::new(&mut self.order);
        self.counts
            .par_chunks_mut(total)
            .zip(keys.par_chunks(chunk))
            .enumerate()
            .for_each(|(c, (slots, keys))| {
                let mut i = (c * chunk) as u32;
                for (k, run) in runs(keys) {
                    let slot = slots[k as usize] as usize;
                    // SAFETY: the prefix gave every (block, chunk) its own slots.
                    let place = unsafe { order.range(slot, run as usize) };
                    for (o, p) in place.iter_mut().zip(i..) {
                        *o = p;
                    }
                    slots[k as usize] += run;
                    i += run;
                }
            });
        // Colours, and the node blocks each occupied block touches (itself and its upper
        // neighbours).
        self.colours.resize(1 << D, Vec::new());
        self.colours.iter_mut().for_each(Vec::clear);
        self.marks.clear();
        self.marks.resize(total, false);
        for (i, (key, _)) in self.occupied.iter().enumerate() {
            let c = self.coords(*key as usize);
            let colour = (0..D).map(|a| (c[a] & 1) << a).sum::<usize>();
            self.colours[colour].push(i as u32);
            for corner in 0..1usize << D {
                let mut key = 0usize;
                let mut inside = true;
                for a in (0..D).rev() {
                    let ca = c[a] + (corner >> a & 1);
                    inside &= ca < blocks[a];
                    key = key * blocks[a] + ca;
                }
                if inside {
                    self.marks[key] = true;
                }
            }
        }
        // Rows: runs of occupied blocks with the same key above axis 0 (consecutive, as the
        // keys ascend with axis 0 fastest).
        let mut rows = Vec::new();
        let mut i = 0;
        while i < self.occupied.len() {
            let row = self.occupied[i].0 as usize / blocks[0];
            let start = self.occupied[i].1.start;
            let mut end = self.occupied[i].1.end;
            i += 1;
            while i < self.occupied.len() && self.occupied[i].0 as usize / blocks[0] == row {
                end = self.occupied[i].1.end;
                i += 1;
            }
            rows.push((row, start..end));
        }
        self.tasks.iter_mut().for_each(Vec::clear);
        // The block (of a row: its first block) of each task, colour by colour.
        let mut cells: Vec<Vec<usize>> = Vec::new();
        let by_rows = rows.len() >= MIN_ROWS;
        if by_rows {
            self.tasks.resize(1 << (D - 1), Vec::new());
            cells.resize(1 << (D - 1), Vec::new());
            for (row, range) in rows {
                let c = self.coords(row * blocks[0]);
                let colour = (1..D).map(|a| (c[a] & 1) << (a - 1)).sum::<usize>();
                self.tasks[colour].push(range);
                cells[colour].push(row * blocks[0]);
            }
        } else {
            self.tasks.resize(1 << D, Vec::new());
            cells.resize(1 << D, Vec::new());
            for ((tasks, cells), colour) in self.tasks.iter_mut().zip(&mut cells).zip(&self.colours)
            {
                tasks.extend(colour.iter().map(|&b| self.occupied[b as usize].1.clone()));
                cells.extend(colour.iter().map(|&b| self.occupied[b as usize].0 as usize));
            }
        }
        self.find_waits(&cells.concat(), by_rows);
        self.node_blocks.clear();
        self.node_blocks.extend(
            self.marks
                .iter()
                .enumerate()
                .filter(|(_, &m)| m)
                .map(|(k, _)| k as u32),
        );
    }

    /// Whether the particles' storage is scattered over their blocks: when the runs of
    /// consecutive slots in `order` are shorter than `SORTED_RUN` on average, the step stores
    /// the particles in `order` (`step::Reorder`: in grid to particle under USL, by
    /// [`crate::particles::Particles::permute`] at the commit otherwise), after which `order`
    /// is one run per block's worth of particles until they move to other blocks.
    pub fn is_scattered(&self, lanes: crate::cpu::Lanes) -> bool {
        let (order, next) = (&self.order[..], self.order.get(1..).unwrap_or_default());
        let breaks: usize = lanes.wide(
            #[inline(always)]
            || {
                let steps = order.iter().zip(next);
                steps
                    .map(|(&a, &b)| usize::from(b != a.wrapping_add(1)))
                    .sum()
            },
        );
        breaks * SORTED_RUN > self.order.len()
    }

    /// Bytes allocated per particle (keys and order) and per block (counts and marks).
    pub fn bytes(&self) -> usize {
        (self.keys.capacity() + self.order.capacity() + self.counts.capacity()) * 4
            + self.marks.capacity()
            + self.occupied.capacity() * std::mem::size_of::<(u32, std::ops::Range<usize>)>()
            + self.node_blocks.capacity() * 4
            + self.colours.iter().map(|c| c.capacity() * 4).sum::<usize>()
    }

    /// Fills `waits`: for each task (`cells[k]` its block, tasks colour by colour) the earlier
    /// tasks whose blocks are within one block of it along every axis (along the axes other than
    /// 0 for rows), which are the tasks that share nodes with it (a block's stencils reach its
    /// own nodes and its upper neighbours'). They are of other colours, as tasks of one colour
    /// are two blocks apart along some axis.
    fn find_waits(&mut self, cells: &[usize], by_rows: bool) {
        let blocks = self.layout.blocks;
        let total: usize = blocks.iter().product();
        let mut task_of = vec![u32::MAX; total];
        for (k, &cell) in cells.iter().enumerate() {
            task_of[cell] = k as u32;
        }
        self.waits.clear();
        self.wait_start.clear();
        self.wait_start.push(0);
        let first_axis = usize::from(by_rows);
        for (k, &cell) in cells.iter().enumerate() {
            let c = self.coords(cell);
            // The neighbours: offsets −1, 0, 1 along each axis from `first_axis` on.
            for offset in 0..3usize.pow((D - first_axis) as u32) {
                let (mut o, mut key, mut inside) = (offset, 0usize, true);
                let mut n = [0usize; D];
                for a in 0..D {
                    n[a] = c[a];
                    if a >= first_axis {
                        let na = c[a] as i64 + (o % 3) as i64 - 1;
                        o /= 3;
                        inside &= na >= 0 && (na as usize) < blocks[a];
                        n[a] = na.max(0) as usize;
                    }
                }
                for a in (0..D).rev() {
                    key = key * blocks[a] + n[a];
                }
                if inside {
                    let t = task_of[key];
                    if t != u32::MAX && (t as usize) < k {
                        self.waits.push(t);
                    }
                }
            }
            self.wait_start.push(self.waits.len() as u32);
        }
    }

    /// Runs `task` on the ranges of `order` of every task of particle to grid, in parallel, and
    /// folds the results with `reduce`: each task starts once the earlier tasks it shares nodes
    /// with ([`Bins::waits_of`]) have ended, so every node's sum is taken in the order of the
    /// colours, as colour after colour would; but a thread that ends its tasks of one colour goes
    /// on with those of the next whose neighbours are done, instead of waiting for the whole
    /// colour to end.
    ///
    /// The threads take the tasks in turn from a shared counter and run each to its end without
    /// calling into rayon, so a task waits only for tasks taken before it that are running on
    /// other threads: the waits end. With one thread every wait is over before it starts.
    pub fn run_tasks<R: Send>(
        &self,
        identity: impl Fn() -> R + Sync + Send,
        task: impl Fn(std::ops::Range<usize>) -> R + Sync + Send,
        reduce: impl Fn(R, R) -> R + Sync + Send,
    ) -> R {
        use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
        let ranges: Vec<&std::ops::Range<usize>> = self.tasks.iter().flatten().collect();
        let n = ranges.len();
        let next = AtomicUsize::new(0);
        let done: Vec<AtomicBool> = (0..n).map(|_| AtomicBool::new(false)).collect();
        let workers = rayon::current_num_threads().clamp(1, n.max(1));
        (0..workers)
            .into_par_iter()
            .map(|_| {
                let mut result = identity();
                loop {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    if k >= n {
                        return result;
                    }
                    for &t in self.waits_of(k) {
                        let mut spins = 0u32;
                        while !done[t as usize].load(Ordering::Acquire) {
                            spins += 1;
                            if spins < 1 << 12 {
                                std::hint::spin_loop();
                            } else {
                                std::thread::yield_now();
                            }
                        }
                    }
                    result = reduce(result, task(ranges[k].clone()));
                    done[k].store(true, Ordering::Release);
                }
            })
            .reduce(&identity, &reduce)
    }

    /// The tasks the `k`-th task of particle to grid (colour by colour) waits for.
    pub fn waits_of(&self, k: usize) -> &[u32] {
        &self.waits[self.wait_start[k] as usize..self.wait_start[k + 1] as usize]
    }

    /// Block coordinates of block `key`.
    fn coords(&self, mut key: usize) -> [usize; D] {
        std::array::from_fn(|a| {
            let c = key % self.layout.blocks[a];
            key /= self.layout.blocks[a];
            c
        })
    }

    /// Appends to `nodes.active` every node of the touched node blocks that was marked touched
    /// and is not listed yet, block by block in ascending order (see
    /// [`GridNodes::collect_touched`]). When nothing is listed yet (the first map of a step),
    /// the blocks are scanned in parallel, once to count their nodes and once to put them into
    /// their stretch of the list: the same list.
    pub fn collect_active(&self, grid: &Grid<D>, nodes: &mut GridNodes<D>) {
        if nodes.active.is_empty() {
            let written = &*nodes;
            let counts: Vec<usize> = self
                .node_blocks
                .par_iter()
                .map(|&key| {
                    let mut count = 0;
                    self.for_each_row(grid, key, |row| count += written.count_written(row));
                    count
                })
                .collect();
            let mut start = Vec::with_capacity(counts.len());
            let mut total = 0;
            for c in counts {
                start.push(total);
                total += c;
            }
            if let Some(list) = nodes.list(total) {
                self.node_blocks
                    .par_iter()
                    .zip(&start)
                    .for_each(|(&key, &start)| {
                        let mut k = start;
                        self.for_each_row(grid, key, |row| {
                            for n in row {
                                // SAFETY: each block puts its own nodes into its own stretch,
                                // whose length the count above took with the same test.
                                unsafe {
                                    if list.is_written(n) {
                                        list.put(k, n);
                                        k += 1;
                                    }
                                }
                            }
                        });
                    });
                return;
            }
        }
        for &key in &self.node_blocks {
            self.for_each_row(grid, key, |row| row.for_each(|n| nodes.collect_touched(n)));
        }
    }

    /// Calls `f` with the storage indices of each row of node block `key` (its nodes along axis
    /// 0, contiguous in storage), the rows in storage order.
    #[inline(always)]
    fn for_each_row(&self, grid: &Grid<D>, key: u32, mut f: impl FnMut(std::ops::Range<usize>)) {
        let (dims, strides) = (grid.dims(), grid.strides());
        debug_assert_eq!(strides[0], 1, "axis 0 is contiguous in node storage");
        let c = self.coords(key as usize);
        let block = self.layout.block;
        let lo: [usize; D] = std::array::from_fn(|a| c[a] * block[a]);
        let hi: [usize; D] = std::array::from_fn(|a| ((c[a] + 1) * block[a]).min(dims[a]));
        let mut i = lo;
        loop {
            let start: usize = (0..D).map(|a| i[a] * strides[a]).sum();
            f(start..start + (hi[0] - lo[0]));
            let mut a = 1;
            loop {
                if a == D {
                    return;
                }
                i[a] += 1;
                if i[a] < hi[a] {
                    break;
                }
                i[a] = lo[a];
                a += 1;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::{scatter_add, NodeScatter};
    use crate::options::Shape;
    use crate::shape::{Stencils, UniformRng};

    /// Particle to grid's schedule ([`Bins::run_tasks`]) from three threads: each particle adds
    /// its quadratic B-spline weights to its nodes' masses, and every node's sum is the one
    /// thread's to the last bit (each node summed in one order whatever the threads do) and
    /// the plain serial sum's to round-off. The grid is 300 × 14 cells, so the particles fill
    /// three blocks along x and four rows of blocks, whose tasks share nodes across every
    /// block face. Run under Miri by `scripts/test-miri.sh`, where two running tasks writing
    /// one node would be a data race.
    #[test]
    fn coloured_tasks_sum_every_node_in_one_order() {
        let shape = Shape::BSpline2.build::<2>().unwrap();
        let mut grid = Grid::<2>::new(Vector::zeros(), [300, 14], 0.1).unwrap();
        grid.set_ghost_layers(shape.ghost_layers()).unwrap();
        let mut rng = UniformRng::new(5);
        let x: Vec<Vector<2>> = (0..240)
            .map(|_| Vector::<2>::new(30.0 * rng.uniform(), 1.4 * rng.uniform()))
            .collect();
        let mut bins = Bins::<2>::default();
        crate::shape::bin_particles(&mut bins, shape.as_ref(), &grid, &x);
        let tasks: usize = bins.tasks.iter().map(Vec::len).sum();
        assert!(tasks >= 6 && bins.tasks.len() > 1, "{tasks} tasks");
        let mut stencils = Stencils::default();
        stencils.compute(shape.as_ref(), &grid, &x);
        let masses = |threads: usize| -> Vec<f64> {
            let mut nodes = GridNodes::<2>::default();
            nodes.ensure(&grid, false, false, false).unwrap();
            {
                let out = NodeScatter::new(&mut nodes);
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                pool.install(|| {
                    bins.run_tasks(
                        || (),
                        |range| {
                            for &p in &bins.order[range] {
                                let (nodes, weights, _) = stencils.of(p as usize);
                                for (&n, &w) in nodes.iter().zip(weights) {
                                    // SAFETY: tasks that share nodes do not run at once
                                    // (`run_tasks` waits for them); `touch` checks the bound.
                                    unsafe {
                                        out.touch(n);
                                        scatter_add(out.mass, n, w * (1.0 + p as f64));
                                    }
                                }
                            }
                        },
                        |(), ()| (),
                    )
                });
            }
            nodes.mass.clone()
        };
        let (one, three) = (masses(1), masses(3));
        assert!(
            one.iter()
                .zip(&three)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "the node sums depend on the thread count"
        );
        let mut serial = vec![0.0; one.len()];
        for p in 0..x.len() {
            let (nodes, weights, _) = stencils.of(p);
            for (&n, &w) in nodes.iter().zip(weights) {
                serial[n] += w * (1.0 + p as f64);
            }
        }
        for (n, (a, b)) in one.iter().zip(&serial).enumerate() {
            assert!(
                (a - b).abs() <= 1e-12 * b.abs().max(1.0),
                "node {n}: {a} against {b}"
            );
        }
        let total: f64 = (0..x.len()).map(|p| 1.0 + p as f64).sum();
        let summed: f64 = one.iter().sum();
        assert!(
            (summed - total).abs() < 1e-9 * total,
            "{summed} against {total}"
        );
    }
}
