//! Materials: one interface ([`Constitutive`]) and the models behind it.
//!
//! Every model works on the 3×3 deformation gradient; a 2D simulation is plane strain
//! (`F_33 = 1`), so the out-of-plane stress is available for the pressure `p = −tr(σ)/3`.
//! Elastic models are a pure function of `F` (no history, no return mapping); plasticity and
//! damage models will carry typed per-particle state.

mod elastic;
mod johnson_cook;
mod plastic;

pub use elastic::{ElasticConstants, LinearElastic, NeoHookean};
pub use johnson_cook::{ofhc_copper, JohnsonCook, JohnsonCookParameters, MieGruneisen};
pub use plastic::{DruckerPrager, History, InertialRheology};

use crate::error::{Error, Result};
use nalgebra::Matrix3;

/// The fastest dilatational (P-) wave speed a material may have, in m/s (material parameters
/// are SI). The fastest real solids are near 1.8e4 m/s (diamond; beryllium 1.3e4 m/s), so no
/// physical material comes near the bound; a faster one is a slip of units or of an exponent
/// (a Young's modulus of 1e300 Pa at 1000 kg/m³ gives 3e148 m/s), and the stable step
/// `h / c` that follows is so small that no run over a physical duration can end.
pub const MAX_WAVE_SPEED: f64 = 1e5;

/// The smallest density a material may have, in kg/m³: about that of interstellar gas, far
/// below any continuum the method models (air is 1.2 kg/m³, the lightest aerogels about 0.2), so
/// a density below it is a slip of units or of an exponent, or a value that has underflowed.
/// It is kept that low because tests and hosts use very light materials on purpose (dust of
/// 1e-13 of a body's mass, to probe the grid's mass floor).
pub const MIN_DENSITY: f64 = 1e-20;

/// Fails unless `density` is at least [`MIN_DENSITY`] and the P-wave speed `wave_speed` of the
/// material is finite, positive and at most [`MAX_WAVE_SPEED`], each with its reason.
pub(crate) fn check_physical(density: f64, wave_speed: f64) -> Result<()> {
    if density.is_nan() || density < MIN_DENSITY {
        return Err(Error::invalid(format!(
            "density {density:e} kg/m³ is below {MIN_DENSITY:e} kg/m³, about that of \
             interstellar gas: no material is that light (material parameters are SI units)"
        )));
    }
    if !(wave_speed.is_finite() && wave_speed > 0.0) {
        return Err(Error::invalid(format!(
            "the material's wave speed is {wave_speed:e} m/s: no stable time step follows \
             from it"
        )));
    }
    if wave_speed > MAX_WAVE_SPEED {
        return Err(Error::invalid(format!(
            "the material's dilatational (P-) wave speed {wave_speed:.3e} m/s \
             exceeds {MAX_WAVE_SPEED:e} m/s, beyond any solid (diamond: about 1.8e4 m/s); its \
             stable step would be h / {wave_speed:.3e} s (material parameters are SI units: \
             Pa and kg/m³)"
        )));
    }
    Ok(())
}

/// What a constitutive model provides to the step.
pub trait Constitutive {
    /// Reference mass density.
    fn density(&self) -> f64;
    /// Longitudinal (P-) wave speed at volume ratio `j = det F`, for the stable time step.
    fn wave_speed(&self, j: f64) -> f64;
    /// Whether the stress is a pure function of `F` (no history, no return mapping).
    fn is_elastic(&self) -> bool;
    /// Cauchy stress for the 3×3 deformation gradient `f` (`det f > 0`).
    fn cauchy_stress(&self, f: &Matrix3<f64>) -> Matrix3<f64>;
    /// Stored elastic energy per unit reference volume at `f`.
    fn strain_energy_density(&self, f: &Matrix3<f64>) -> f64;
}

/// A material of the simulation.
#[derive(Debug, Clone, PartialEq)]
pub enum Material {
    /// Small-strain linear elasticity, `σ = λ tr(ε) I + 2 μ ε`, `ε = sym(F) − I` (for verification).
    LinearElastic(LinearElastic),
    /// Compressible neo-Hookean, `σ = μ/J (F Fᵀ − I) + λ ln J / J I`.
    NeoHookean(NeoHookean),
    /// Drucker–Prager soil (Hencky elasticity, non-associated flow, apex return).
    DruckerPrager(DruckerPrager),
    /// J2 plasticity with Johnson–Cook hardening and damage, optional Mie–Grüneisen EOS.
    JohnsonCook(JohnsonCook),
    /// A rigid body moving with a prescribed constant velocity (needs contact).
    Rigid(Rigid),
}

/// A rigid body: density (for its mass) and prescribed velocity (the first `dim` components).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rigid {
    pub density: f64,
    pub velocity: [f64; 3],
}

impl Constitutive for Rigid {
    fn density(&self) -> f64 {
        self.density
    }
    fn wave_speed(&self, _j: f64) -> f64 {
        0.0
    }
    fn is_elastic(&self) -> bool {
        true
    }
    fn cauchy_stress(&self, _f: &Matrix3<f64>) -> Matrix3<f64> {
        Matrix3::zeros()
    }
    fn strain_energy_density(&self, _f: &Matrix3<f64>) -> f64 {
        0.0
    }
}

impl Material {
    /// Linear elastic material from density, Young's modulus and Poisson's ratio.
    pub fn linear_elastic(density: f64, young: f64, poisson: f64) -> Result<Self> {
        Ok(Material::LinearElastic(LinearElastic(
            ElasticConstants::new(density, young, poisson)?,
        )))
    }

    /// Compressible neo-Hookean material from density, Young's modulus and Poisson's ratio.
    pub fn neo_hookean(density: f64, young: f64, poisson: f64) -> Result<Self> {
        Ok(Material::NeoHookean(NeoHookean(ElasticConstants::new(
            density, young, poisson,
        )?)))
    }

    /// Drucker–Prager soil: density, Young's modulus, Poisson's ratio, friction angle (degrees),
    /// cohesion (Pa) and dilatancy angle (degrees, at most the friction angle).
    pub fn drucker_prager(
        density: f64,
        young: f64,
        poisson: f64,
        friction_degrees: f64,
        cohesion: f64,
        dilatancy_degrees: f64,
    ) -> Result<Self> {
        Ok(Material::DruckerPrager(DruckerPrager::new(
            ElasticConstants::new(density, young, poisson)?,
            friction_degrees,
            cohesion,
            dilatancy_degrees,
        )?))
    }

    /// Johnson–Cook metal (see [`JohnsonCookParameters`]).
    pub fn johnson_cook(parameters: JohnsonCookParameters) -> Result<Self> {
        Ok(Material::JohnsonCook(JohnsonCook::new(parameters)?))
    }

    /// A rigid body of density `density` moving with `velocity` (only the first `dim` components
    /// are used). Fails for a density not finite or below [`MIN_DENSITY`], or a non-finite
    /// velocity.
    pub fn rigid(density: f64, velocity: [f64; 3]) -> Result<Self> {
        crate::error::check_positive("density", density)?;
        if density < MIN_DENSITY {
            return Err(Error::invalid(format!(
                "density {density:e} kg/m³ is below {MIN_DENSITY:e} kg/m³, about that of \
                 interstellar gas: no material is that light (material parameters are SI units)"
            )));
        }
        for v in velocity {
            crate::error::check_finite("velocity", v)?;
        }
        Ok(Material::Rigid(Rigid { density, velocity }))
    }

    /// Whether the material gives `field` values of its own, beyond the zero every other
    /// material reads: plastic strain for the elastoplastic materials, damage for Johnson–Cook
    /// with damage; every other field for every material.
    pub fn carries(&self, field: crate::particles::Field) -> bool {
        use crate::particles::Field;
        match field {
            Field::PlasticStrain => {
                matches!(self, Material::DruckerPrager(_) | Material::JohnsonCook(_))
            }
            Field::Damage => matches!(self, Material::JohnsonCook(j) if j.p.damage.is_some()),
            _ => true,
        }
    }

    /// The prescribed velocity of a rigid body.
    pub fn rigid_velocity<const D: usize>(&self) -> Option<crate::Vector<D>> {
        match self {
            Material::Rigid(r) => Some(crate::Vector::<D>::from_fn(|i, _| r.velocity[i])),
            _ => None,
        }
    }

    /// The constitutive update of a history model over `dt`: new state and Cauchy stress after
    /// the increment `df = F^{n+1} (F^n)⁻¹`, for the new `det F = j`. Elastic models have no
    /// history and never get here (the step calls [`Constitutive::cauchy_stress`]).
    pub fn plastic_update(
        &self,
        state: &History,
        df: &Matrix3<f64>,
        j: f64,
        dt: f64,
    ) -> (History, Matrix3<f64>) {
        match self {
            Material::DruckerPrager(m) => m.update(state, df, j, dt),
            Material::JohnsonCook(m) => m.update(state, df, j, dt),
            Material::LinearElastic(_) | Material::NeoHookean(_) | Material::Rigid(_) => {
                unreachable!("elastic materials have no history")
            }
        }
    }

    /// Stored elastic energy per unit reference volume of a point with deformation `f` and, for
    /// history models, state `state`.
    pub fn stored_energy(&self, f: &Matrix3<f64>, state: Option<&History>) -> f64 {
        match (self, state) {
            (Material::DruckerPrager(m), Some(s)) => {
                m.elastic_energy(&s.elastic_deformation) * f.determinant()
                    / s.elastic_deformation.determinant()
            }
            (Material::JohnsonCook(m), Some(s)) => {
                m.stored_energy(s) * f.determinant() / s.elastic_deformation.determinant()
            }
            _ => self.strain_energy_density(f),
        }
    }
}

impl Constitutive for JohnsonCook {
    fn density(&self) -> f64 {
        self.elastic.density
    }
    fn wave_speed(&self, j: f64) -> f64 {
        JohnsonCook::wave_speed(self, j)
    }
    fn is_elastic(&self) -> bool {
        false
    }
    /// The elastic stress of `f` taken as wholly elastic and undamaged (no return mapping).
    fn cauchy_stress(&self, f: &Matrix3<f64>) -> Matrix3<f64> {
        let svd = f.svd(true, false);
        let u = svd.u.expect("U");
        let eps = svd.singular_values.map(|s| s.ln());
        let dev = eps - nalgebra::Vector3::repeat(eps.sum() / 3.0);
        let j = f.determinant();
        u * Matrix3::from_diagonal(&(2.0 * self.elastic.mu / j * dev)) * u.transpose()
            - Matrix3::identity() * self.pressure(j, 0.0)
    }
    fn strain_energy_density(&self, f: &Matrix3<f64>) -> f64 {
        self.elastic_energy(f)
    }
}

impl Constitutive for DruckerPrager {
    fn density(&self) -> f64 {
        self.elastic.density
    }
    fn wave_speed(&self, _j: f64) -> f64 {
        ((self.elastic.lambda + 2.0 * self.elastic.mu) / self.elastic.density).sqrt()
    }
    fn is_elastic(&self) -> bool {
        false
    }
    /// The elastic (Hencky) stress of `f` taken as wholly elastic (no return mapping).
    fn cauchy_stress(&self, f: &Matrix3<f64>) -> Matrix3<f64> {
        self.elastic_stress(f, f.determinant())
    }
    fn strain_energy_density(&self, f: &Matrix3<f64>) -> f64 {
        self.elastic_energy(f)
    }
}

/// Calls `$e` with `$m` bound to the model inside a [`Material`], dispatched statically so that
/// the elastic stress of the hot loop inlines.
macro_rules! each_model {
    ($material:expr, $m:ident => $e:expr) => {
        match $material {
            Material::Rigid($m) => $e,
            Material::LinearElastic($m) => $e,
            Material::NeoHookean($m) => $e,
            Material::DruckerPrager($m) => $e,
            Material::JohnsonCook($m) => $e,
        }
    };
}

impl Constitutive for Material {
    #[inline]
    fn density(&self) -> f64 {
        each_model!(self, m => m.density())
    }
    #[inline]
    fn wave_speed(&self, j: f64) -> f64 {
        each_model!(self, m => m.wave_speed(j))
    }
    #[inline]
    fn is_elastic(&self) -> bool {
        each_model!(self, m => m.is_elastic())
    }
    #[inline]
    fn cauchy_stress(&self, f: &Matrix3<f64>) -> Matrix3<f64> {
        each_model!(self, m => m.cauchy_stress(f))
    }
    fn strain_energy_density(&self, f: &Matrix3<f64>) -> f64 {
        each_model!(self, m => m.strain_energy_density(f))
    }
}

impl Material {
    /// The `D×D` block of the Cauchy stress and the pressure of an elastic material at the
    /// `D×D` deformation gradient `f` with `j = det f > 0`. Linear elastic and neo-Hookean
    /// work on the block directly (no 3×3 embedding); the others go through
    /// [`Constitutive::cauchy_stress`].
    #[inline(always)]
    pub fn elastic_stress<const D: usize>(
        &self,
        f: &crate::Matrix<D>,
        j: f64,
    ) -> (crate::Matrix<D>, f64) {
        match self {
            Material::NeoHookean(m) => m.stress_block(f, j),
            Material::LinearElastic(m) => m.stress_block(f),
            m => {
                let s = m.cauchy_stress(&embed3(f));
                (block(&s), pressure(&s))
            }
        }
    }

    /// [`Material::elastic_stress`] and the wave speed at `j` ([`Constitutive::wave_speed`]),
    /// with one logarithm for neo-Hookean.
    #[inline(always)]
    pub fn elastic_stress_and_wave_speed<const D: usize>(
        &self,
        f: &crate::Matrix<D>,
        j: f64,
    ) -> ((crate::Matrix<D>, f64), f64) {
        match self {
            Material::NeoHookean(m) => {
                let ln_j = j.ln();
                (
                    m.stress_block_with_log(f, j, ln_j),
                    m.wave_speed_from_log(ln_j),
                )
            }
            m => (m.elastic_stress(f, j), m.wave_speed(j)),
        }
    }
}

/// Embeds a `D×D` deformation gradient in 3×3 (plane strain in 2D).
pub fn embed3<const D: usize>(f: &crate::Matrix<D>) -> Matrix3<f64> {
    let mut f3 = Matrix3::identity();
    f3.view_mut((0, 0), (D, D)).copy_from(f);
    f3
}

/// The `D×D` block of a 3×3 tensor.
pub fn block<const D: usize>(s: &Matrix3<f64>) -> crate::Matrix<D> {
    s.fixed_view::<D, D>(0, 0).into_owned()
}

/// Pressure `p = −tr(σ)/3` of a 3×3 Cauchy stress.
pub fn pressure(s: &Matrix3<f64>) -> f64 {
    -s.trace() / 3.0
}
