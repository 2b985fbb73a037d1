//! The uniform background grid: geometry, node indexing and the node fields that a step writes.
//!
//! The grid covers the domain `[origin, origin + cells * h]` per axis. Around it lie `ghost` layers
//! of extra nodes, so that every shape function has its full stencil for any particle inside the
//! domain: partition of unity and linear reproduction then hold up to the grid's faces with no
//! boundary-modified splines. Wall conditions fold the ghost layers back onto the domain (see
//! [`crate::walls`]).
//!
//! Node storage is dense, but a step only visits the nodes that particles touched (the
//! `active` list) and resets only those.

use crate::error::{check_finite, check_positive, Error, ErrorKind, Result};
use crate::Vector;

mod blocks;
mod shared;
pub use blocks::{Bins, BlockLayout};
use shared::is_written;
pub use shared::{scatter_add, NodeList, NodeScatter, SharedSlice};

/// Geometry of the background grid. Nodes have integer indices `-ghost ..= cells + ghost` per axis.
#[derive(Debug, Clone, PartialEq)]
pub struct Grid<const D: usize> {
    pub(crate) origin: Vector<D>,
    pub(crate) cell_size: f64,
    pub(crate) cells: [usize; D],
    ghost: usize,
    /// Nodes per axis including ghost layers.
    dims: [usize; D],
    strides: [usize; D],
}

impl<const D: usize> Grid<D> {
    /// A grid with `cells[a]` cells of size `cell_size` along axis `a`, starting at `origin`.
    ///
    /// Fails when the cell size is not positive, the origin is not finite, or a cell count is zero
    /// or so large that the node count would overflow.
    pub fn new(origin: Vector<D>, cells: [usize; D], cell_size: f64) -> Result<Self> {
        check_positive("cell_size", cell_size)?;
        for a in 0..D {
            check_finite("origin", origin[a])?;
            if cells[a] == 0 {
                return Err(Error::invalid(format!("cells[{a}] must be at least 1")));
            }
            if cells[a] > 1 << 24 {
                return Err(Error::invalid(format!(
                    "cells[{a}] = {} is larger than 2^24",
                    cells[a]
                )));
            }
            let far = origin[a] + cells[a] as f64 * cell_size;
            check_finite("origin + cells * cell_size", far)?;
        }
        let mut g = Grid {
            origin,
            cell_size,
            cells,
            ghost: 0,
            dims: [0; D],
            strides: [0; D],
        };
        g.set_ghost_layers(0)?;
        Ok(g)
    }

    /// The lower corner of the domain.
    pub fn origin(&self) -> Vector<D> {
        self.origin
    }

    /// The cells' edge length.
    pub fn cell_size(&self) -> f64 {
        self.cell_size
    }

    /// The cells per axis.
    pub fn cells(&self) -> [usize; D] {
        self.cells
    }

    /// Sets the number of ghost node layers (chosen from the shape function's support).
    pub fn set_ghost_layers(&mut self, ghost: usize) -> Result<()> {
        let mut stride = 1usize;
        let mut dims = [0; D];
        let mut strides = [0; D];
        for a in 0..D {
            dims[a] = self.cells[a] + 1 + 2 * ghost;
            strides[a] = stride;
            stride = stride
                .checked_mul(dims[a])
                .filter(|&s| s <= 1 << 34)
                .ok_or_else(|| Error::invalid("grid has too many nodes (more than 2^34)"))?;
        }
        self.ghost = ghost;
        self.dims = dims;
        self.strides = strides;
        Ok(())
    }

    pub fn ghost_layers(&self) -> usize {
        self.ghost
    }

    /// Stored nodes per axis, ghost layers included.
    pub fn dims(&self) -> [usize; D] {
        self.dims
    }

    /// The cells along the grid's widest axis.
    pub fn cells_across(&self) -> usize {
        self.cells.iter().copied().max().unwrap_or(0)
    }

    /// Storage index step per axis.
    pub fn strides(&self) -> [usize; D] {
        self.strides
    }

    /// Total number of stored nodes, ghost layers included.
    pub fn node_count(&self) -> usize {
        self.dims.iter().product()
    }

    /// Upper corner of the domain.
    pub fn upper(&self) -> Vector<D> {
        Vector::<D>::from_fn(|a, _| self.origin[a] + self.cells[a] as f64 * self.cell_size)
    }

    /// Whether `x` lies inside the closed domain box.
    pub fn contains(&self, x: &Vector<D>) -> bool {
        self.domain().contains(x)
    }

    /// The closed domain box, with its upper corner computed once (for tests per particle).
    pub fn domain(&self) -> DomainBox<D> {
        DomainBox {
            lower: self.origin,
            upper: self.upper(),
        }
    }

    /// Linear storage index of the node with integer index `i` (each in `-ghost ..= cells+ghost`).
    #[inline]
    pub fn node_index(&self, i: [i64; D]) -> usize {
        let mut n = 0usize;
        for (a, &ia) in i.iter().enumerate() {
            let s = ia + self.ghost as i64;
            debug_assert!(s >= 0 && (s as usize) < self.dims[a], "node outside grid");
            n += s as usize * self.strides[a];
        }
        n
    }

    /// Integer node index of storage index `n`.
    #[inline]
    pub fn node_multi_index(&self, mut n: usize) -> [i64; D] {
        let mut i = [0i64; D];
        for a in (0..D).rev() {
            i[a] = (n / self.strides[a]) as i64 - self.ghost as i64;
            n %= self.strides[a];
        }
        i
    }

    /// Position of the node with integer index `i`.
    #[inline]
    pub fn node_position(&self, i: [i64; D]) -> Vector<D> {
        Vector::<D>::from_fn(|a, _| self.origin[a] + i[a] as f64 * self.cell_size)
    }

    /// Position of `x` in cell units relative to the origin.
    #[inline]
    pub fn to_cell_units(&self, x: &Vector<D>) -> Vector<D> {
        (x - self.origin) / self.cell_size
    }
}

/// Node fields written during one step, with the list of nodes that were touched.
#[derive(Debug, Default, Clone)]
pub struct GridNodes<const D: usize> {
    pub mass: Vec<f64>,
    pub momentum: Vec<Vector<D>>,
    pub force: Vec<Vector<D>>,
    /// Velocity at the start of the step (`momentum / mass`), used by FLIP.
    pub velocity_old: Vec<Vector<D>>,
    /// Velocity after the grid update and boundary conditions.
    pub velocity: Vec<Vector<D>>,
    /// For signed shape functions only (`None` otherwise): the nonnegative lumping's masses and
    /// each node's blend, from which `step::edge_lumping` makes the transfer weights.
    pub lumping: Option<EdgeLumping>,
    /// Mass gradient `Σ_p m_p ∇Ψ_I(x_p)` for contact normals; empty unless contact is on.
    pub mass_gradient: Vec<Vector<D>>,
    /// Body force `Σ_p m_p Ψ_I b_p` kept apart from `force` (which then holds the internal force
    /// and tractions), so that the grid update can limit the internal force of edge nodes and
    /// still apply the body force exactly; empty unless that limit is on (signed shape functions
    /// and VC integration).
    pub body_force: Vec<Vector<D>>,
    /// Nodes a scatter marked. The factored B-spline scatter marks none when it maps mass
    /// (nonnegative weights: a node it reaches gets mass), so `collect_touched` also takes a
    /// node with mass as touched.
    touched: Vec<bool>,
    /// Position of each touched node in `active` (valid only for touched nodes).
    slot: Vec<u32>,
    /// Storage indices of the touched nodes, in the order they were first touched.
    pub active: Vec<usize>,
}

impl<const D: usize> GridNodes<D> {
    /// Sizes the storage for `grid`, with the edge lumping of signed shape functions
    /// (`lumping`) and the mass gradient of contact (`mass_gradient`) when asked for. Does nothing
    /// when the storage already fits; otherwise all fields start at zero with nothing active.
    /// All or nothing: when the storage cannot be allocated (`OutOfMemory`), the nodes are left
    /// as they were.
    pub fn ensure(
        &mut self,
        grid: &Grid<D>,
        lumping: bool,
        mass_gradient: bool,
        body_force: bool,
    ) -> Result<()> {
        let n = grid.node_count();
        if self.mass.len() == n
            && self.lumping.is_some() == lumping
            && (self.mass_gradient.len() == n) == mass_gradient
            && (self.body_force.len() == n) == body_force
        {
            return Ok(());
        }
        let fail = |e: std::collections::TryReserveError| {
            let per_node = std::mem::size_of::<f64>()
                * (1 + 4 * D
                    + usize::from(mass_gradient) * D
                    + usize::from(body_force) * D
                    + usize::from(lumping) * 2)
                + 5;
            Error::new(
                ErrorKind::OutOfMemory,
                format!(
                    "the grid's node storage ({n} nodes, about {:.1} GiB) cannot be allocated \
                     ({e}); use fewer or larger cells",
                    (n as f64 * per_node as f64) / (1u64 << 30) as f64
                ),
            )
        };
        let nodes = GridNodes {
            mass: filled(n, 0.0).map_err(fail)?,
            momentum: filled(n, Vector::zeros()).map_err(fail)?,
            force: filled(n, Vector::zeros()).map_err(fail)?,
            velocity_old: filled(n, Vector::zeros()).map_err(fail)?,
            velocity: filled(n, Vector::zeros()).map_err(fail)?,
            lumping: match lumping {
                true => Some(EdgeLumping::new(n).map_err(fail)?),
                false => None,
            },
            mass_gradient: match mass_gradient {
                true => filled(n, Vector::zeros()).map_err(fail)?,
                false => Vec::new(),
            },
            body_force: match body_force {
                true => filled(n, Vector::zeros()).map_err(fail)?,
                false => Vec::new(),
            },
            touched: filled(n, false).map_err(fail)?,
            slot: filled(n, 0).map_err(fail)?,
            active: Vec::new(),
        };
        *self = nodes;
        Ok(())
    }

    /// Bytes allocated.
    pub fn bytes(&self) -> usize {
        let v = std::mem::size_of::<Vector<D>>();
        let lumping = self
            .lumping
            .as_ref()
            .map_or(0, |l| (l.mass.capacity() + l.blend.capacity()) * 8);
        self.mass.capacity() * 8
            + (self.momentum.capacity()
                + self.force.capacity()
                + self.velocity_old.capacity()
                + self.velocity.capacity()
                + self.mass_gradient.capacity()
                + self.body_force.capacity())
                * v
            + lumping
            + self.touched.capacity()
            + self.slot.capacity() * 4
            + self.active.capacity() * std::mem::size_of::<usize>()
    }

    /// The slot of node `n` in `active`, if it is listed there.
    #[inline]
    pub fn slot_of(&self, n: usize) -> Option<usize> {
        let slot = *self.slot.get(n)? as usize;
        (self.active.get(slot) == Some(&n)).then_some(slot)
    }

    /// Whether node `n` was written this step.
    #[inline]
    pub fn is_touched(&self, n: usize) -> bool {
        self.touched.get(n).copied().unwrap_or(false)
    }

    /// Marks node `n` as written this step and returns its position in `active`.
    #[inline]
    pub fn touch(&mut self, n: usize) -> usize {
        if !self.touched[n] {
            self.touched[n] = true;
            self.slot[n] = self.active.len() as u32;
            self.active.push(n);
        }
        self.slot[n] as usize
    }

    /// Lists node `n` in `active` if a parallel scatter ([`NodeScatter`]) marked it touched or
    /// gave it mass, and it is not listed yet (`slot` and `active` point at each other exactly
    /// for listed nodes).
    #[inline]
    pub fn collect_touched(&mut self, n: usize) {
        if is_written(self.touched[n], self.mass[n]) {
            self.touched[n] = true;
            let s = self.slot[n] as usize;
            if s >= self.active.len() || self.active[s] != n {
                self.slot[n] = self.active.len() as u32;
                self.active.push(n);
            }
        }
    }

    /// How many nodes of `nodes` (a range of storage indices) [`GridNodes::collect_touched`]
    /// would list: marked touched or given mass.
    #[inline(always)]
    pub fn count_written(&self, nodes: std::ops::Range<usize>) -> usize {
        let (touched, mass) = (&self.touched[nodes.clone()], &self.mass[nodes]);
        touched
            .iter()
            .zip(mass)
            .map(|(&t, &m)| usize::from(is_written(t, m)))
            .sum()
    }

    /// When nothing is listed yet: room for `count` nodes in `active`, and a [`NodeList`] that
    /// puts nodes there from several threads. `None`, having changed nothing, when nodes are
    /// listed already.
    pub fn list(&mut self, count: usize) -> Option<NodeList<'_>> {
        if !self.active.is_empty() {
            return None;
        }
        assert!(
            count <= u32::MAX as usize,
            "active nodes fit their 32-bit slots"
        );
        self.active.resize(count, 0);
        Some(NodeList {
            active: SharedSlice::new(&mut self.active),
            slot: SharedSlice::new(&mut self.slot),
            touched: SharedSlice::new(&mut self.touched),
            mass: &self.mass,
        })
    }

    /// Position of touched node `n` in `active`.
    #[inline]
    pub fn slot(&self, n: usize) -> usize {
        debug_assert!(self.touched[n]);
        self.slot[n] as usize
    }

    /// Zeroes the nodes written this step, and only those.
    pub fn reset(&mut self) {
        use rayon::prelude::*;
        let GridNodes {
            mass,
            momentum,
            force,
            velocity_old,
            velocity,
            lumping,
            mass_gradient,
            body_force,
            touched,
            active,
            ..
        } = self;
        let scalars = [SharedSlice::new(mass)];
        let vectors = [
            momentum,
            force,
            velocity_old,
            velocity,
            mass_gradient,
            body_force,
        ]
        .map(|v| SharedSlice::new(v.as_mut_slice()));
        let touched = SharedSlice::new(touched);
        // The blend stays: VC reads it after the transfer weights are made (`edge_lumping`).
        let lumped_mass = lumping.as_mut().map(|l| SharedSlice::new(&mut l.mass));
        // SAFETY: `active` lists each node once, so every node is written by one task only;
        // empty fields (not kept) are skipped.
        active.par_iter().for_each(|&n| unsafe {
            let zero = |s: &[SharedSlice<'_, Vector<D>>]| {
                s.iter()
                    .filter(|v| !v.is_empty())
                    .for_each(|v| *v.at(n) = Vector::zeros())
            };
            scalars.iter().for_each(|m| *m.at(n) = 0.0);
            zero(&vectors);
            *touched.at(n) = false;
            if let Some(m) = &lumped_mass {
                *m.at(n) = 0.0;
            }
        });
        active.clear();
    }

    /// Whether every node is zero and inactive (for tests of the reset).
    pub fn is_clear(&self) -> bool {
        self.active.is_empty()
            && self.mass.iter().all(|&m| m == 0.0)
            && self.momentum.iter().all(|p| p.norm_squared() == 0.0)
            && self.force.iter().all(|f| f.norm_squared() == 0.0)
            && !self.touched.iter().any(|&t| t)
    }
}

/// The closed box `[lower, upper]` of a grid's domain ([`Grid::domain`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DomainBox<const D: usize> {
    pub lower: Vector<D>,
    pub upper: Vector<D>,
}

impl<const D: usize> DomainBox<D> {
    /// Whether `x` lies inside the box (its faces included).
    #[inline]
    pub fn contains(&self, x: &Vector<D>) -> bool {
        (0..D).all(|a| x[a] >= self.lower[a] && x[a] <= self.upper[a])
    }
}

/// Per-node sums of signed shape functions' nonnegative lumping (`step::edge_lumping`).
#[derive(Debug, Default, Clone)]
pub struct EdgeLumping {
    /// `Σ_p m_p L_I(x_p)`.
    pub mass: Vec<f64>,
    /// `θ` of each node ([`EdgeLumping::blend`]).
    pub blend: Vec<f64>,
}

impl EdgeLumping {
    fn new(n: usize) -> std::result::Result<Self, std::collections::TryReserveError> {
        Ok(EdgeLumping {
            mass: filled(n, 0.0)?,
            blend: filled(n, 1.0)?,
        })
    }

    /// Weight `θ ∈ [0, 1]` of the shape-function lumping at a node with lumped masses
    /// `m_Ψ = Σ m_p Ψ_I` and `m_L = Σ m_p L_I`: 1 where `m_Ψ ≥ 3/4 m_L` (inside a body, where
    /// both are close to `ρ h^d`), 0 where `m_Ψ ≤ 1/4 m_L` (a node that barely overlaps the body,
    /// where `m_Ψ` can be tiny or negative), a smooth step between.
    #[inline]
    pub fn blend(mass_shape: f64, mass_lumping: f64) -> f64 {
        if mass_lumping <= 0.0 {
            return 1.0;
        }
        let s = ((mass_shape / mass_lumping - 0.25) / 0.5).clamp(0.0, 1.0);
        s * s * (3.0 - 2.0 * s)
    }
}

/// `n` copies of `value`, or the allocation error instead of an abort.
fn filled<T: Clone>(
    n: usize,
    value: T,
) -> std::result::Result<Vec<T>, std::collections::TryReserveError> {
    let mut v = Vec::new();
    v.try_reserve_exact(n)?;
    v.resize(n, value);
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn node_index_round_trip_with_ghosts() {
        let mut g = Grid::<3>::new(Vector::<3>::new(-1.0, 0.0, 2.0), [4, 5, 6], 0.5).unwrap();
        g.set_ghost_layers(2).unwrap();
        assert_eq!(g.node_count(), 9 * 10 * 11);
        for n in 0..g.node_count() {
            assert_eq!(g.node_index(g.node_multi_index(n)), n);
        }
        assert_eq!(g.node_index([-2, -2, -2]), 0);
        assert_eq!(
            g.node_position([1, 0, -1]),
            Vector::<3>::new(-0.5, 0.0, 1.5)
        );
        assert_eq!(g.upper(), Vector::<3>::new(1.0, 2.5, 5.0));
    }

    #[test]
    fn rejects_bad_geometry() {
        assert!(Grid::<2>::new(Vector::<2>::zeros(), [0, 3], 1.0).is_err());
        assert!(Grid::<2>::new(Vector::<2>::zeros(), [3, 3], 0.0).is_err());
        assert!(Grid::<2>::new(Vector::<2>::zeros(), [3, 3], f64::NAN).is_err());
        assert!(Grid::<2>::new(Vector::<2>::new(f64::INFINITY, 0.0), [3, 3], 1.0).is_err());
    }
}
