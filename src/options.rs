//! The options of a simulation, declared once for every layer.
//!
//! Each choice is a Rust enum whose variants may carry parameters (`Shape::Rk { order, support }`),
//! and a parameter-free *kind* (`ShapeKind`): a `#[repr(u32)]` enum whose discriminants are the
//! codes of the C API (`RKMPM_SHAPE_*`) and of checkpoint files, and whose serde names (feature
//! `serde`) are the spellings of scene files (`shape = "bspline2"`). `TryFrom<u32>` turns a code
//! into a kind and refuses unknown codes; `kind()` and `from_kind` go between a kind and its
//! option. The constants of the C API (`capi/`) and of the Fortran module spell the same codes
//! for their users; tests check both against these kinds.
//!
//! This module imports nothing else of the engine, so every module can import it.

use crate::Vector;
use num_enum::{IntoPrimitive, TryFromPrimitive};

/// The shape functions of the grid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Shape {
    /// Linear hats (standard MPM, C0).
    Linear,
    /// Quadratic B-spline (C1).
    BSpline2,
    /// Cubic B-spline (C2).
    BSpline3,
    /// Reproducing kernel of basis order `order` with normalized support `support` (`ã`, the
    /// kernel support in cells): about 2 for order 1 (where it equals the cubic B-spline), 3 for
    /// order 2, 3.5 to 4 for order 3.
    Rk { order: u32, support: f64 },
}

/// Which [`Shape`], without its parameters (`RKMPM_SHAPE_*`; scene files: `shape`).
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, TryFromPrimitive, IntoPrimitive)]
#[cfg_attr(feature = "serde", derive(serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum ShapeKind {
    Linear = 0,
    #[default]
    Bspline2 = 1,
    Bspline3 = 2,
    Rk = 3,
}

impl Shape {
    /// Whether VC of order 1 corrects with the particles' linear fit (and so keeps angular
    /// momentum): it needs every particle's support to hold at least three nodes of
    /// non-negligible weight along each axis. The cubic B-spline and RK with `ã ≥ 2` do; linear
    /// hats have two, and the quadratic B-spline two at a cell's centre, where the fit would
    /// leave the correction one free value per particle in 2D and `K` (nearly) singular along
    /// the fields linear on every cell. These take the mean alone.
    pub fn vc_linear_fit(&self) -> bool {
        match self {
            Shape::BSpline3 => true,
            Shape::Rk { support, .. } => *support >= 2.0,
            Shape::Linear | Shape::BSpline2 => false,
        }
    }

    pub fn kind(&self) -> ShapeKind {
        match self {
            Shape::Linear => ShapeKind::Linear,
            Shape::BSpline2 => ShapeKind::Bspline2,
            Shape::BSpline3 => ShapeKind::Bspline3,
            Shape::Rk { .. } => ShapeKind::Rk,
        }
    }

    /// The shape of `kind`; `order` and `support` are read only for [`ShapeKind::Rk`].
    pub fn from_kind(kind: ShapeKind, order: u32, support: f64) -> Shape {
        match kind {
            ShapeKind::Linear => Shape::Linear,
            ShapeKind::Bspline2 => Shape::BSpline2,
            ShapeKind::Bspline3 => Shape::BSpline3,
            ShapeKind::Rk => Shape::Rk { order, support },
        }
    }
}

/// How the weak form is integrated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Integration {
    /// Material-point integration (particles are the quadrature points).
    #[default]
    MaterialPoint,
    /// Variationally consistent integration of the given order: test-function gradients
    /// corrected so the divergence equality of that order holds.
    Vc { order: u32 },
}

/// Which [`Integration`], without its order (`RKMPM_INTEGRATION_*`; scene files: `integration`).
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, TryFromPrimitive, IntoPrimitive)]
#[cfg_attr(feature = "serde", derive(serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum IntegrationKind {
    #[default]
    MaterialPoint = 0,
    Vc = 1,
}

impl Integration {
    pub fn kind(&self) -> IntegrationKind {
        match self {
            Integration::MaterialPoint => IntegrationKind::MaterialPoint,
            Integration::Vc { .. } => IntegrationKind::Vc,
        }
    }

    /// The integration of `kind`; `order` is read only for [`IntegrationKind::Vc`].
    pub fn from_kind(kind: IntegrationKind, order: u32) -> Integration {
        match kind {
            IntegrationKind::MaterialPoint => Integration::MaterialPoint,
            IntegrationKind::Vc => Integration::Vc { order },
        }
    }
}

/// Particle ↔ grid velocity transfer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Transfer {
    /// `v_p ← (1 − α) v_PIC + α v_FLIP` with `α = flip` in `[0, 1]`.
    PicFlip { flip: f64 },
    /// Affine particle-in-cell (Jiang et al. 2015).
    Apic,
    /// Moving-least-squares MPM (Hu et al. 2018): APIC whose internal force and velocity
    /// gradient take the MLS gradient `M⁻¹ Ψ_I (x_I − x_p)` in place of `∇Ψ_I`, so the force
    /// rides on the affine momentum (one scatter of mass and momentum per node, no force sum)
    /// and the velocity gradient is the affine matrix `C_p`. Quadratic and cubic B-splines only
    /// (`M = h²/4`, `h²/3`), without VC (else the first step fails with `Unsupported`); the
    /// transfer of Taichi's and Warp's MPM examples. Faster than APIC (about 1.15× per step in
    /// 2D, 1.25× in 3D) but less accurate: the MLS gradient is exact for linear fields only, so
    /// on a smooth solution it converges at about first order where APIC with the B-spline
    /// gradient reaches second (`docs/convergence`).
    Mls,
}

/// Which [`Transfer`], without its FLIP weight (`RKMPM_TRANSFER_*`; scene files: `transfer`).
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, TryFromPrimitive, IntoPrimitive)]
#[cfg_attr(feature = "serde", derive(serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum TransferKind {
    PicFlip = 0,
    #[default]
    Apic = 1,
    Mls = 2,
}

impl Transfer {
    /// Whether particles keep an affine matrix `C_p` (APIC and MLS).
    pub fn is_affine(&self) -> bool {
        matches!(self, Transfer::Apic | Transfer::Mls)
    }

    pub fn kind(&self) -> TransferKind {
        match self {
            Transfer::PicFlip { .. } => TransferKind::PicFlip,
            Transfer::Apic => TransferKind::Apic,
            Transfer::Mls => TransferKind::Mls,
        }
    }

    /// The transfer of `kind`; `flip` is read only for [`TransferKind::PicFlip`].
    pub fn from_kind(kind: TransferKind, flip: f64) -> Transfer {
        match kind {
            TransferKind::PicFlip => Transfer::PicFlip { flip },
            TransferKind::Apic => Transfer::Apic,
            TransferKind::Mls => Transfer::Mls,
        }
    }
}

/// Where the stress update and the second velocity map sit (`RKMPM_SCHEME_*`; scene files:
/// `scheme`).
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, TryFromPrimitive, IntoPrimitive)]
#[cfg_attr(feature = "serde", derive(serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum Scheme {
    /// Update stress last: the velocity gradient uses the grid velocities of the grid update.
    #[default]
    Usl = 0,
    /// Modified USL (Sulsky 1995): particle momenta are mapped to the grid a second time after the
    /// particle velocity update, and the velocity gradient uses those grid velocities.
    Musl = 1,
}

/// The condition on one face of the grid (a wall); `boundary` applies it.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Wall {
    #[default]
    Free,
    /// No velocity on the face (no-slip).
    Fixed,
    /// No normal velocity on the face (roller), tangential motion free.
    Slip,
    /// Unilateral contact with Coulomb friction coefficient `μ ≥ 0`.
    Friction(f64),
}

/// Which [`Wall`], without its friction (`RKMPM_BOUNDARY_*`; scene files: `kind` of a wall).
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, TryFromPrimitive, IntoPrimitive)]
#[cfg_attr(feature = "serde", derive(serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum WallKind {
    #[default]
    Free = 0,
    Fixed = 1,
    Slip = 2,
    Friction = 3,
}

impl Wall {
    pub fn kind(&self) -> WallKind {
        match self {
            Wall::Free => WallKind::Free,
            Wall::Fixed => WallKind::Fixed,
            Wall::Slip => WallKind::Slip,
            Wall::Friction(_) => WallKind::Friction,
        }
    }

    /// The friction coefficient (0 for a wall without friction).
    pub fn friction(&self) -> f64 {
        match *self {
            Wall::Friction(mu) => mu,
            _ => 0.0,
        }
    }

    /// The wall of `kind`; `friction` is read only for [`WallKind::Friction`].
    pub fn from_kind(kind: WallKind, friction: f64) -> Wall {
        match kind {
            WallKind::Free => Wall::Free,
            WallKind::Fixed => Wall::Fixed,
            WallKind::Slip => Wall::Slip,
            WallKind::Friction => Wall::Friction(friction),
        }
    }
}

/// Which face of an axis (scene files: `side`; the C API passes −1 and +1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum Side {
    Low = 0,
    High = 1,
}

/// The conditions on all `2 D` faces.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Walls<const D: usize> {
    pub faces: [[Wall; 2]; D],
}

impl<const D: usize> Default for Walls<D> {
    fn default() -> Self {
        Walls {
            faces: [[Wall::Free; 2]; D],
        }
    }
}

/// Contact between bodies (`contact` applies it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Contact {
    /// Coulomb friction coefficient `μ ≥ 0` between bodies.
    pub friction: f64,
}

/// Options of a simulation; the ones marked "before stepping" are fixed by the first step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options<const D: usize> {
    /// Before stepping. Default: quadratic B-spline.
    pub shape: Shape,
    /// Before stepping. Default: material-point integration.
    pub integration: Integration,
    /// Before stepping. Default: APIC.
    pub transfer: Transfer,
    /// Before stepping. Default: USL.
    pub scheme: Scheme,
    pub gravity: Vector<D>,
    pub walls: Walls<D>,
    /// Before stepping. Default: none (one velocity field; bodies stick where they meet).
    pub contact: Option<Contact>,
}

impl<const D: usize> Default for Options<D> {
    fn default() -> Self {
        Options {
            shape: Shape::from_kind(ShapeKind::default(), 0, 0.0),
            integration: Integration::default(),
            transfer: Transfer::from_kind(TransferKind::default(), 0.0),
            scheme: Scheme::default(),
            gravity: Vector::<D>::zeros(),
            walls: Walls::default(),
            contact: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every kind's code goes to its kind and back, its option has that kind, and the first
    /// code past the last is refused.
    #[test]
    fn kinds_round_trip_through_their_codes() {
        for code in 0..4u32 {
            let k = ShapeKind::try_from(code).unwrap();
            assert_eq!(u32::from(k), code);
            assert_eq!(Shape::from_kind(k, 2, 3.0).kind(), k);
            let w = WallKind::try_from(code).unwrap();
            assert_eq!(u32::from(w), code);
            assert_eq!(Wall::from_kind(w, 0.5).kind(), w);
        }
        for code in 0..3u32 {
            let k = TransferKind::try_from(code).unwrap();
            assert_eq!(Transfer::from_kind(k, 0.5).kind(), k);
        }
        for code in 0..2u32 {
            let k = IntegrationKind::try_from(code).unwrap();
            assert_eq!(Integration::from_kind(k, 2).kind(), k);
            assert_eq!(u32::from(Scheme::try_from(code).unwrap()), code);
        }
        assert!(ShapeKind::try_from(4).is_err());
        assert!(WallKind::try_from(4).is_err());
        assert!(TransferKind::try_from(3).is_err());
        assert!(IntegrationKind::try_from(2).is_err());
        assert!(Scheme::try_from(2).is_err());
    }

    /// The parameters a kind carries survive the round trip.
    #[test]
    fn from_kind_keeps_the_parameters() {
        assert_eq!(
            Shape::from_kind(ShapeKind::Rk, 2, 3.0),
            Shape::Rk {
                order: 2,
                support: 3.0
            }
        );
        assert_eq!(
            Integration::from_kind(IntegrationKind::Vc, 2),
            Integration::Vc { order: 2 }
        );
        assert_eq!(
            Transfer::from_kind(TransferKind::PicFlip, 0.25),
            Transfer::PicFlip { flip: 0.25 }
        );
        assert_eq!(Wall::Friction(0.3).friction(), 0.3);
        assert_eq!(
            Wall::from_kind(WallKind::Friction, 0.3),
            Wall::Friction(0.3)
        );
        let o = Options::<2>::default();
        assert_eq!((o.shape, o.transfer), (Shape::BSpline2, Transfer::Apic));
    }
}

/// The fast paths of the step, one switch per simulation (`Sim::set_fast_paths`). Each is on by
/// default; off, the step takes the plain path. Both paths compute the same method: the same
/// bits for `vector_instructions`, the same up to the order of the node sums (round-off) for the
/// others. Tests and benchmarks compare the two; a user has no reason to turn one off.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FastPaths {
    /// The particle loops compiled for AVX2 and FMA where the processor has them (and
    /// `RKMPM_PORTABLE=1` is not set).
    pub vector_instructions: bool,
    /// B-spline stencils (and RK1's with ã = 2, the cubic B-spline's) stored as 1D factors per
    /// axis, rather than node by node as RK's (with VC, the transfers take the factors and VC's
    /// sums the lists).
    pub factored_stencils: bool,
    /// The particles' storage kept in the order of their grid blocks (`Particles`); off, it
    /// stays in id order and scenes whose particles mix run slower.
    pub particle_sorting: bool,
}

impl Default for FastPaths {
    fn default() -> Self {
        FastPaths {
            vector_instructions: true,
            factored_stencils: true,
            particle_sorting: true,
        }
    }
}

/// How VTK files store their arrays (`RKMPM_VTK_*`; scene files: `vtk` of `[run]`).
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, TryFromPrimitive, IntoPrimitive)]
#[cfg_attr(feature = "serde", derive(serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum VtkFormat {
    /// Raw little-endian bytes appended after the XML (`<AppendedData encoding="raw">`), as
    /// ParaView writes them: exact values, written many times faster; 0.4 to 0.6 of the text's
    /// size for moving bodies, larger than the text for bodies at rest (the text writes a zero
    /// in three characters).
    #[default]
    Binary = 0,
    /// Numbers as text (`format="ascii"`), each the shortest decimal that reads back exactly.
    Ascii = 1,
}
