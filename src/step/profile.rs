//! Wall-clock time per phase of the steps, so that a benchmark shows which phase moved.

use std::time::Instant;

/// Seconds spent in each phase of the steps taken so far (summed over steps).
#[derive(Debug, Default, Clone, Copy, PartialEq)]
pub struct PhaseTimes {
    /// Binning particles by grid block, and clearing the nodes the last step wrote (beside it).
    pub bins: f64,
    /// Shape-function values and gradients (and RK moment solves).
    pub shape: f64,
    /// Finding the surface of the particles (VC without given boundary points).
    pub surface: f64,
    /// Body forces, boundary points and VC corrections.
    pub forces_and_vc: f64,
    pub particle_to_grid: f64,
    pub grid_update: f64,
    pub grid_to_particle: f64,
    /// Constitutive update (stress, return mapping).
    pub constitutive: f64,
    /// Checks of the new state.
    pub checks: f64,
    /// Committing the new state.
    pub commit: f64,
}

impl PhaseTimes {
    /// The phases with their names, in step order.
    pub fn phases(&self) -> [(&'static str, f64); 10] {
        [
            ("bins", self.bins),
            ("shape", self.shape),
            ("surface", self.surface),
            ("forces_vc", self.forces_and_vc),
            ("p2g", self.particle_to_grid),
            ("grid", self.grid_update),
            ("g2p", self.grid_to_particle),
            ("constitutive", self.constitutive),
            ("checks", self.checks),
            ("commit", self.commit),
        ]
    }

    /// Sum over the phases.
    pub fn total(&self) -> f64 {
        self.phases().iter().map(|p| p.1).sum()
    }
}

/// Seconds since `clock`, which is reset to now.
#[inline]
pub(crate) fn lap(clock: &mut Instant) -> f64 {
    let now = Instant::now();
    let dt = now.duration_since(*clock).as_secs_f64();
    *clock = now;
    dt
}

/// Bytes a simulation holds, by part (capacities of its arrays).
#[derive(Debug, Default, Clone, Copy, PartialEq)]
pub struct MemoryUse {
    pub particles: usize,
    /// Per-particle step storage: stencils, the new state being built, bins, volumes.
    pub particle_workspace: usize,
    /// Node storage (dense over the grid, ghost layers included; a step touches only the
    /// active nodes).
    pub grid: usize,
    /// Nodes written by the last step.
    pub active_nodes: usize,
    pub particle_count: usize,
    pub node_count: usize,
}

impl MemoryUse {
    /// Particle storage and particle workspace per particle.
    pub fn bytes_per_particle(&self) -> f64 {
        (self.particles + self.particle_workspace) as f64 / self.particle_count.max(1) as f64
    }

    /// Node storage per stored node.
    pub fn bytes_per_node(&self) -> f64 {
        self.grid as f64 / self.node_count.max(1) as f64
    }
}

/// Bytes of a vector's allocation.
pub(crate) fn bytes<T>(v: &Vec<T>) -> usize {
    v.capacity() * std::mem::size_of::<T>()
}
