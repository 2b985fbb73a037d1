//! What a step works with: the scratch space kept between steps ([`Workspace`]), what every
//! phase reads and none changes ([`StepInputs`]), the transfer's and the found surface's plans
//! for the step, and how the step stores its particles ([`Reorder`]).

use super::checks::StepLabel;
use super::grid_to_particle::NewState;
use super::profile::PhaseTimes;
use super::{BodyFields, BoundaryUpdate};
use crate::energy::NodeLosses;
use crate::grid::{Bins, Grid, GridNodes};
use crate::integration::BoundaryPoints;
use crate::material::Material;
use crate::options::{FastPaths, Options, Walls};
use crate::particles::Particles;
use crate::shape::{ShapeFunction, Stencils, TensorStencils};
use crate::Vector;

/// Scratch space of a step, kept between steps so the hot loops do not allocate.
#[derive(Debug, Default)]
pub struct Workspace<const D: usize> {
    /// Particles binned by grid block (the coloured particle-to-grid map).
    pub bins: Bins<D>,
    /// Stored stencils (RK, and every shape under VC).
    pub stencils: Stencils<D>,
    /// B-spline stencils as 1D factors (linear hats, quadratic, cubic).
    pub linear: TensorStencils<D, 2>,
    pub quadratic: TensorStencils<D, 3>,
    pub cubic: TensorStencils<D, 4>,
    /// Buffers of the particles' sort.
    pub(crate) spare: crate::particles::SpareArrays<D>,
    /// How the step being taken stores its particles in block order (decided with its bins).
    pub reorder: Reorder,
    /// Permute every quantity at the commit even under USL (tests compare the two ways).
    pub reorder_at_commit: bool,
    /// `max_p (c_p + |v_p|)` of the particles as they are, when the last step computed it with
    /// their new state (`None` after anything else changed them: `Sim::signal_speed` then takes
    /// it afresh); and the value of the step being taken, which its commit makes current.
    pub signal_speed: Option<f64>,
    pub new_signal_speed: f64,
    /// Time per phase, summed over the steps.
    pub times: PhaseTimes,
    /// Nodes written by the last step.
    pub active_nodes: usize,
    pub boundary_stencils: Stencils<D>,
    /// Current particle volumes (for VC).
    pub volumes: Vec<f64>,
    pub boundary_updates: Vec<BoundaryUpdate<D>>,
    /// What the step's friction walls and contact correction took from the node velocities.
    pub node_losses: NodeLosses,
    pub nodes: GridNodes<D>,
    /// The bodies' node fields under contact; empty otherwise.
    pub bodies: BodyFields<D>,
    pub body_acceleration: Vec<Vector<D>>,
    /// The new particle state, swapped in by the commit.
    pub new_state: NewState<D>,
    /// Whether each new particle state passed the checks.
    pub admissible: Vec<bool>,
}

/// How a step stores its particles in the order of their grid blocks, once they have scattered
/// over them (`Bins::is_scattered`).
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub enum Reorder {
    /// Not this step: still sorted enough, or sorting is off.
    #[default]
    No,
    /// Grid to particle writes the new state in block order, and the commit permutes only the
    /// quantities a step carries unchanged (USL): a fifth of the bytes of a whole permutation.
    InGather,
    /// The commit permutes every quantity (MUSL, whose second map reads the new state by the
    /// particles' old slots).
    AtCommit,
}

/// What the transfer needs from the particles and the shape function.
#[derive(Debug, Clone, Copy)]
pub struct TransferPlan {
    /// FLIP weight (0 for pure PIC and for APIC).
    pub flip: f64,
    /// APIC is on.
    pub apic: bool,
    /// `1 / D_p` when the shape function's APIC inertia is a constant multiple of the identity.
    pub inverse_inertia: Option<f64>,
    /// MLS: the force rides on the affine momentum and the velocity gradient is `C_p` (then
    /// `apic` is on and `inverse_inertia` is given).
    pub mls: bool,
}

impl TransferPlan {
    /// `1 / D_p` under MLS (whose force rides on the affine momentum), `None` otherwise.
    pub fn mls_inverse_inertia(&self) -> Option<f64> {
        self.inverse_inertia.filter(|_| self.mls)
    }
}

/// What the phases of one step read and none of them changes.
pub(crate) struct StepInputs<'a, const D: usize, S> {
    pub grid: &'a Grid<D>,
    pub particles: &'a Particles<D>,
    /// The particles' shape functions this step.
    pub stencils: &'a S,
    /// The same as stored lists, when they are (for VC and the lumping of signed shapes).
    pub stored: Option<&'a Stencils<D>>,
    /// The particles binned by grid block for the maps to the grid.
    pub bins: &'a Bins<D>,
    pub walls: &'a Walls<D>,
    pub options: &'a Options<D>,
    pub shape: &'a dyn ShapeFunction<D>,
    pub materials: &'a [Material],
    /// Each material's rigid velocity, `None` for a deformable one.
    pub rigid: &'a [Option<Vector<D>>],
    /// The body-force callback's accelerations this step, if there is one.
    pub body_acceleration: Option<&'a [Vector<D>]>,
    /// The given boundary points.
    pub boundary: &'a BoundaryPoints<D>,
    pub fast_paths: FastPaths,
    pub label: StepLabel,
    pub plan: TransferPlan,
    pub surface_plan: SurfacePlan,
    pub dt: f64,
}

/// The found surface's age after a step taken with `plan` (`carried`: its points moved): 1
/// after the step that found it and carried it, one more after each step that carried it,
/// `u32::MAX` (found anew by the next step) when not carried.
pub(crate) fn surface_age_after(age: u32, plan: SurfacePlan, carried: bool) -> u32 {
    match (carried, plan.find) {
        (true, true) => 1,
        (true, false) => age.saturating_add(1),
        (false, _) => u32::MAX,
    }
}

/// How a step takes the surface VC finds from the particles (no boundary points given):
/// found anew from the particles at its start, or the last one as the grid carried it; and
/// whether the step carries it on to the next (METHOD.md section 3: the found surface).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct SurfacePlan {
    /// Find the surface from the particles at the start of the step.
    pub find: bool,
    /// Move the surface with the grid like given boundary points, for the next step.
    pub carry: bool,
}

/// Clears the nodes the last step wrote (all fields zero, none active), of the one field and of
/// each body's.
pub(super) fn clear_grid<const D: usize>(nodes: &mut GridNodes<D>, bodies: &mut [GridNodes<D>]) {
    nodes.reset();
    for b in bodies.iter_mut() {
        b.reset();
    }
}

impl<const D: usize> Workspace<D> {
    /// Clears the nodes the last step wrote (all fields zero, none active), of the one field
    /// and of each body's; the step does it itself, while it bins.
    pub fn clear_grid(&mut self) {
        clear_grid(&mut self.nodes, &mut self.bodies.nodes);
    }
}
